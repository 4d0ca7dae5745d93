"""The LLM instruction interpreter: ``--agent llm:MODEL@http://HOST:PORT/v1``.

An :class:`~icrsumo.agents.privileged.InstructionFollower` whose language understanding is a
language model behind any OpenAI-compatible chat-completions server (vLLM, llama.cpp's server,
a hosted API) instead of the rule-based intent classifier (``instruction-follower``, the
``rules`` interpreter). It drives as the instruction-follower does (privileged lane keeping and
junction execution, no access to the route) and asks the model which maneuver to make:

* whenever the active instruction changes (``at = "instruction"``), and
* within :data:`ASK_M` of each junction that offers a choice (``at = "junction"``), under the
  instruction then active.

The request holds the instruction text exactly as the agent received it and a compact scene
(:class:`Scene`: speed, lane k of n, distance to the next junction with a choice and its
branches, traffic-light state, gap to the vehicle ahead), and asks for JSON
``{"maneuver": M}`` with M from :data:`MENU` (through the server's structured-output support:
``format=json_object`` sends the schema as llama.cpp's servers take it, ``json_schema`` as the
OpenAI API and vLLM take it, ``none`` sends none). Any other answer is an *invalid answer*: the
agent follows its lane, and the episode counts it. ``stop`` brings the car to a standstill for
:data:`STOP_HOLD_S`, after which it follows the road. Temperature 0 and a fixed seed are sent.
When the run has asking on, the menu also offers ``ask`` (:data:`SYSTEM_ASKING`,
:data:`SCHEMA_ASKING`): the agent then asks the navigator (:mod:`icrsumo.sim.asking`) as the
instruction-follower does for an instruction it cannot place, and the exchange is stored with
maneuver ``unknown``.

Every exchange is stored with the episode (:class:`icrsumo.core.types.ModelCall` in its log) and
in a content-addressed response cache (``OUT/llm-cache``, key: SHA-256 of the exact request,
which names the model): a rerun, a resume, ``icrsumo show`` and ``icrsumo attack``'s replays
are answered from it without a server and give byte-identical episodes.

Spec: ``llm:MODEL@URL[?key_env=VAR&image=1&format=json_object&timeout=S&seed=N]``; the API key
is read from the environment variable ``key_env`` names (never from the command line). The key
(or a password in the URL) goes to the URL's own origin only, and is redacted from whatever the
server sends back (:mod:`icrsumo.core.llmio`). A response that is not an OpenAI-compatible answer (an
HTML page) is a server fault, never the model's answer: it is not cached.

:mod:`icrsumo.agents.llm_request` holds the settings, the scene, the request and the answer's
reading (no network); its names are importable from here too.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from icrsumo.core.errors import Field, InputError, display_url
from icrsumo.core.llmio import (
    ResponseCache,
    ServerFault,
    Transport,
    answer_text,
    canonical,
    chat_url,
    exchange,
    http_problem,
    models_url,
    request_hash,
    served_models,
    unwritable,
)
from icrsumo.core.types import Intent, ModelCall

from .base import Action, AgentError, EpisodeInfo, Observation, World
from .driver import lane_edge, lane_index
from .llm_request import (
    ASK,
    FORMATS,
    LLM_PREFIX,
    LOOK_M,
    MAX_TOKENS,
    MENU,
    PROMPT_VERSION,
    SCHEMA,
    SCHEMA_ASKING,
    SYSTEM,
    SYSTEM_ASKING,
    Answer,
    LLMSettings,
    Scene,
    answer_of,
    api_key,
    build_request,
    parse_answer,
    parse_spec,
    user_message,
    with_format,
    with_options,
)
from .privileged import InstructionFollower

#: the agent's names and, re-exported, those of llm_request
__all__ = [
    "ASK_M", "Asker", "LEAD_HALF_WIDTH", "LEAD_M", "LLMFactory", "LLMFollower", "LOGGED_ANSWER",
    "MAX_ANSWER_BYTES", "RETRIES", "RETRY_BACKOFF", "STANDING", "STOP_HOLD_S", "bound",
    "check_server", "llm_factory", "ASK", "FORMATS", "LLM_PREFIX", "LOOK_M", "MAX_TOKENS", "MENU",
    "PROMPT_VERSION", "SCHEMA", "SCHEMA_ASKING", "SYSTEM", "SYSTEM_ASKING", "Answer", "LLMSettings", "Scene",
    "answer_of",
    "api_key", "build_request", "parse_answer", "parse_spec", "user_message", "with_format",
    "with_options",
]

#: m before a junction with a choice within which the model is asked about it
ASK_M = 40.0
#: m ahead within which a vehicle in the ego's lane is reported
LEAD_M = 100.0
#: m lateral half-width of the ego's lane for the vehicle ahead
LEAD_HALF_WIDTH = 1.8
#: s the car stands still after a "stop" answer before it follows the road again
STOP_HOLD_S = 5.0
#: m/s below which the car counts as standing
STANDING = 0.1
#: bytes of a response body read at most; a larger one is a server fault
MAX_ANSWER_BYTES = 64 << 10
#: characters of an answer kept in the episode log
LOGGED_ANSWER = 500
#: extra attempts after a transport failure or a server error before the episode crashes
RETRIES = 1
#: s slept before a retry
RETRY_BACKOFF = 0.5

_LIGHTS = {"r": "red", "R": "red", "y": "yellow", "Y": "yellow", "G": "green", "g": "green",
           "s": "none (stop sign)", "w": "none (all-way stop)"}
_BRANCH = {"s": "straight", "l": "left", "L": "left", "r": "right", "R": "right", "t": "u-turn"}
_BRANCH_ORDER = ("left", "straight", "right", "u-turn")


# --------------------------------------------------------------------------- the client
@dataclass
class Asker:
    """Answers requests from the response cache, else from the server (one request at a time,
    bounded in time and size). Transport failures and server faults that persist raise
    :class:`AgentError`; only the model's answers (``content``) are cached."""

    settings: LLMSettings
    key: str | None = None
    memory: dict[str, dict] = field(default_factory=dict)
    #: requests sent to the server / answered from the cache (memory or disk)
    sent: int = 0
    hits: int = 0

    def __post_init__(self) -> None:
        self.cache = ResponseCache(self.settings.cache_dir) if self.settings.cache_dir is not None else None

    def ask(self, body: dict, asking: bool = False) -> tuple[str, Answer]:
        """(cache key, answer) of the request ``body`` (``asking``: :data:`ASK` is an answer)."""
        key, rec = self.record(body)
        return key, answer_of(rec, asking)

    def record(self, body: dict) -> tuple[str, dict]:
        """(cache key, cache record: the answer's ``content``) of the request ``body``."""
        key = request_hash(body)
        rec = self.memory.get(key)
        if rec is None and self.cache is not None:
            rec = self.cache.get(key, body)
            if rec is not None and not isinstance(rec.get("content"), str):
                rec = None   # a server fault an earlier icrsumo stored as an answer: ask again
        if rec is not None:
            self.hits += 1
        else:
            rec = self._fetch(body)
            if self.cache is not None:
                self.cache.put(key, body, **rec)
        self.memory[key] = rec
        return key, rec

    def _fetch(self, body: dict) -> dict:
        s = self.settings
        url = chat_url(s.endpoint)
        problem = ""
        for attempt in range(1 + RETRIES):
            if attempt:
                time.sleep(RETRY_BACKOFF * attempt)
            try:
                reply = exchange(url, canonical(body), api_key=self.key, timeout=s.timeout,
                                 limit=MAX_ANSWER_BYTES)
                self.sent += 1
                if reply.status == 200:
                    return {"content": answer_text(reply)[0]}
            except Transport as err:
                problem = f"timed out after {s.timeout:g} s" if str(err) == "timed out" else str(err)
                continue
            problem = http_problem(reply)
            if 400 <= reply.status < 500 and reply.status not in (408, 429):
                break
        where = " (the run began with it unreachable: answers came from the cache only)" if s.offline else ""
        raise AgentError(f"LLM server {display_url(url)} for model {s.model}: {problem}{where}")


# --------------------------------------------------------------------------- the agent
class LLMFollower(InstructionFollower):
    """An instruction-follower whose instruction understanding is a language model (module
    docstring). ``calls``: the episode's exchanges so far (:class:`icrsumo.core.types.ModelCall`)."""

    def __init__(self, settings: LLMSettings) -> None:
        super().__init__()
        self.settings = settings
        self.name = settings.name
        self.asker = Asker(settings, api_key(settings))
        self.calls: list[ModelCall] = []
        self._asked: set[tuple[tuple[int, bool], str]] = set()
        self._stop_since: float | None = None   # s: when the car came to a standstill after "stop"
        self._stopping = False

    def reset(self, info: EpisodeInfo) -> None:
        super().reset(info)
        self.calls = []
        self._asked = set()
        self._stopping = False
        self._stop_since = None

    def episode_calls(self) -> tuple[ModelCall, ...]:
        """The exchanges of the episode (the episode loop stores them in its log)."""
        return tuple(self.calls)

    # ---- protocol
    def act(self, obs: Observation) -> Action:
        action = super().act(obs)
        if self._stopping:
            if obs.speed < STANDING:
                self._stop_since = obs.t if self._stop_since is None else self._stop_since
                if obs.t - self._stop_since >= STOP_HOLD_S:
                    self._stopping, self._stop_since = False, None
            if self._stopping:
                return replace(action, target_speed=0.0)
        return action

    def interpret(self, obs: Observation) -> Intent:
        """Ask the model at an instruction change (the instruction-follower's hook)."""
        if obs.instruction_id < 0:
            return Intent.FOLLOW
        return self._ask(obs, "instruction")

    def observe(self, obs: Observation) -> None:
        changed = (obs.instruction_id, obs.answer) != self._instr_id
        super().observe(obs)   # asks when the instruction changed
        w = obs.world
        if w is None or obs.instruction_id < 0 or not w.lane or w.lane.startswith(":"):
            return
        edge = lane_edge(w.lane)
        options = self._options(edge)
        ahead = self.net.lane_length.get(w.lane, 0.0) - w.lane_pos
        if len(options) < 2 or ahead > ASK_M or (self._instr_id, edge) in self._asked:
            return
        self._asked.add((self._instr_id, edge))
        if changed:   # just asked, with this junction in the scene
            return
        intent = self.placed(self._ask(obs, "junction"), obs)
        if intent != self.intent:
            self.intent = intent
            self._decided.pop(edge, None)
        self._spent = None   # the model decided for this junction

    # ---- asking
    def _ask(self, obs: Observation, at: str) -> Intent:
        scene = self.scene(obs)
        png = self._png(obs) if self.settings.image else None
        body = build_request(self.settings, obs.instruction, scene, png, self.asking)
        key, answer = self.asker.ask(body, self.asking)
        self.calls.append(ModelCall(
            t=round(float(obs.t), 3), instruction_id=int(obs.instruction_id), at=at, key=key,
            prompt=user_message(obs.instruction, scene), answer=answer.text[:LOGGED_ANSWER],
            maneuver=answer.maneuver, valid=answer.valid, problem=answer.problem))
        self._stopping = answer.maneuver is Intent.STOP
        self._stop_since = None
        return answer.maneuver

    def scene(self, obs: Observation) -> Scene:
        """The :class:`Scene` of ``obs`` (its privileged world view)."""
        w = obs.world
        assert w is not None, "the LLM agent is privileged: it needs the World view"
        net = self.net
        lane, lanes, junction_m, branches, light = 0, 0, None, (), "none"
        if w.lane and not w.lane.startswith(":") and w.lane in net.lane_length:
            edge, idx = lane_edge(w.lane), lane_index(w.lane)
            own = net.passenger_lanes.get(edge, ())
            lanes = len(own)
            lane = 1 + sum(1 for i in own if i < idx)
            dist = net.lane_length[w.lane] - w.lane_pos
            seen = {edge}
            while dist <= LOOK_M:
                options = self._options(edge)
                if len(options) >= 2:
                    junction_m = max(0.0, dist)
                    conns = [c for o in options for c in net.connections[(edge, o)]]
                    dirs = {_BRANCH.get(c.direction, "straight") for c in conns}
                    branches = tuple(b for b in _BRANCH_ORDER if b in dirs)
                    mine = [c for c in conns if c.from_lane == idx] or conns
                    light = self._light(w, mine[0])
                    break
                if not options or options[0] in seen:
                    break
                edge = options[0]
                seen.add(edge)
                idx = -1
                dist += net.edge_length.get(edge, 0.0)
        return Scene(speed=float(obs.speed), lane=lane, lanes=lanes, junction_m=junction_m,
                     branches=branches, light=light, lead_m=self._lead(w))

    def _light(self, w: World, conn) -> str:
        if not conn.tls:
            return _LIGHTS.get(conn.state, "none")
        return _LIGHTS.get(self._signal(w, conn), "off")

    def _lead(self, w: World) -> float | None:
        """m from the ego's front to the nearest vehicle's rear in the ego's lane ahead."""
        v = w.vehicles
        if not len(v):
            return None
        c, s = math.cos(w.ego.yaw), math.sin(w.ego.yaw)
        dx, dy = v[:, 0] - w.ego.x, v[:, 1] - w.ego.y
        ahead, side = dx * c + dy * s, -dx * s + dy * c
        gap = ahead - 0.5 * (self.params.length + v[:, 3])
        mask = (ahead > 0) & (np.abs(side) < LEAD_HALF_WIDTH) & (gap < LEAD_M)
        return float(max(0.0, gap[mask].min())) if mask.any() else None

    def _png(self, obs: Observation) -> bytes:
        from icrsumo.render import png_bytes, to_rgb

        return png_bytes(to_rgb(obs.bev))


# --------------------------------------------------------------------------- the factory
class LLMFactory:
    """``agent_factory`` of ``llm:MODEL@URL``: makes an :class:`LLMFollower` per episode.
    :meth:`bind` checks the server (before any episode runs) and points the agents at an out
    folder's response cache; ``fingerprint`` covers the agent's code, the model and every
    setting that changes a request (not the server's address or key)."""

    privileged = True
    needs_route = False
    agent_class = LLMFollower

    def __init__(self, settings: LLMSettings) -> None:
        self.settings = settings
        self.name = settings.name
        self._checked = settings.cache_dir is not None

    @property
    def fingerprint(self) -> str:
        from .identity import fingerprint, of_text

        s = self.settings
        return of_text(json.dumps({"code": fingerprint(LLMFollower), "model": s.model, "image": s.image,
                                   "format": s.format, "seed": s.seed, "max_tokens": MAX_TOKENS,
                                   "prompt": PROMPT_VERSION}, sort_keys=True))

    def bind(self, out: Path) -> LLMFactory:
        """A factory whose agents keep their answers in ``out/llm-cache`` (:func:`bound`)."""
        return LLMFactory(bound(self.settings, out))

    def __call__(self) -> LLMFollower:
        if not self._checked:   # an agent made outside an evaluation (check-agent, the env)
            check_server(self.settings, has_cache=False)
            self._checked = True
        return LLMFollower(self.settings)


def bound(s: LLMSettings, out: Path, option: Field = Field("agents")) -> LLMSettings:
    """``s`` keeping its answers in ``out/llm-cache``, after checking (before any episode runs)
    that answers can be stored there and :func:`check_server`; a server that is unreachable is
    accepted when that cache holds answers (the run is then answered from it)."""
    cache_dir = Path(out) / "llm-cache"
    why = unwritable(cache_dir)
    if why:
        raise InputError(cache_dir, "", f"the LLM response cache cannot be written: {why}",
                         "make it writable (or move the file out of the way), or use another out folder")
    offline = check_server(s, len(ResponseCache(cache_dir)) > 0, option)
    return replace(s, cache_dir=cache_dir, offline=offline)


def check_server(s: LLMSettings, has_cache: bool, option: Field = Field("agents")) -> bool:
    """Check the API key variable and that the server answers (within ``s.timeout``) as an
    OpenAI-compatible server and serves ``s.model``; InputErrors naming ``option`` and the fix.
    Returns True (offline) when the server is unreachable but ``has_cache`` (the run is
    answered from the cache)."""
    key = api_key(s, option)
    start = "start it (e.g. icrsumo serve-llm --port 8080 for SmolLM2), or fix the URL"
    endpoint = display_url(s.endpoint)
    try:
        models = served_models(s.endpoint, api_key=key, timeout=s.timeout)
    except ServerFault as err:
        raise InputError(option, s.name, f"the LLM server {display_url(models_url(s.endpoint))} {err}",
                         "give the URL of an OpenAI-compatible API (it usually ends in /v1)") from None
    except Transport as err:
        if err.unreachable and has_cache:
            return True
        why = f"timed out after {s.timeout:g} s" if str(err) == "timed out" else str(err)
        raise InputError(option, s.name, f"the LLM server {endpoint} does not answer ({why})",
                         start if err.unreachable else "check the server and its API key") from None
    if models is not None and s.model not in models:
        shown = ", ".join(models[:8]) + (", ..." if len(models) > 8 else "")
        raise InputError(option, s.name, f"the LLM server {endpoint} does not serve model {s.model!r} "
                         f"(it serves: {shown or 'none'})", "name a model it serves after llm:")
    return False


def llm_factory(spec: str) -> LLMFactory:
    """The factory of an ``llm:MODEL@URL`` spec (no network: :meth:`LLMFactory.bind` checks)."""
    return LLMFactory(parse_spec(spec))
