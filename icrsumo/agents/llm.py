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

Every exchange is stored with the episode (:class:`icrsumo.types.ModelCall` in its log) and
in a content-addressed response cache (``OUT/llm-cache``, key: SHA-256 of the exact request,
which names the model): a rerun, a resume, ``icrsumo show`` and ``icrsumo attack``'s replays
are answered from it without a server and give byte-identical episodes.

Spec: ``llm:MODEL@URL[?key_env=VAR&image=1&format=json_object&timeout=S&seed=N]``; the API key
is read from the environment variable ``key_env`` names (never from the command line). The key
(or a password in the URL) goes to the URL's own origin only, and is redacted from whatever the
server sends back (:mod:`icrsumo.llmio`). A response that is not an OpenAI-compatible answer (an
HTML page) is a server fault, never the model's answer: it is not cached.
"""

from __future__ import annotations

import base64
import json
import math
import os
import re
import time
import urllib.parse
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import Field, InputError, check_key_env, check_key_text, display_url
from ..llmio import (
    Invalid,
    ResponseCache,
    ServerFault,
    Transport,
    answer_text,
    canonical,
    chat_url,
    exchange,
    http_problem,
    is_http,
    models_url,
    request_hash,
    served_models,
    unwritable,
)
from ..types import Intent, ModelCall
from .base import Action, AgentError, EpisodeInfo, Observation, World
from .privileged import InstructionFollower, _lane_edge, _lane_index

#: the spec prefix (:data:`icrsumo.agents.registry.LLM_PREFIX`, which dispatches to this module)
LLM_PREFIX = "llm:"

#: the maneuvers a model may answer (Intent values)
MENU: tuple[Intent, ...] = (Intent.FOLLOW, Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT,
                            Intent.LANE_LEFT, Intent.LANE_RIGHT, Intent.STOP)
#: structured-output request styles
FORMATS = ("json_object", "json_schema", "none")
#: m before a junction with a choice within which the model is asked about it
ASK_M = 40.0
#: m ahead searched for the next junction with a choice (along the road's only continuation)
LOOK_M = 200.0
#: m ahead within which a vehicle in the ego's lane is reported
LEAD_M = 100.0
#: m lateral half-width of the ego's lane for the vehicle ahead
LEAD_HALF_WIDTH = 1.8
#: s the car stands still after a "stop" answer before it follows the road again
STOP_HOLD_S = 5.0
#: m/s below which the car counts as standing
STANDING = 0.1
#: tokens an answer may have (the JSON answer needs about 10)
MAX_TOKENS = 32
#: bytes of a response body read at most; a larger one is a server fault
MAX_ANSWER_BYTES = 64 << 10
#: characters of an answer kept in the episode log
LOGGED_ANSWER = 500
#: extra attempts after a transport failure or a server error before the episode crashes
RETRIES = 1
#: s slept before a retry
RETRY_BACKOFF = 0.5
#: changes whenever the prompt's wording changes (part of the agent's fingerprint)
PROMPT_VERSION = "1"

SYSTEM = (
    "You are the language module of a self-driving car. The car steers, keeps its lane, keeps "
    "its distance and obeys traffic lights by itself. Your only job is to read the instruction "
    "it was given and choose the maneuver to make now or at the next junction.\n"
    "Maneuvers: follow = keep following the current road; left = turn left at the next "
    "junction; right = turn right at the next junction; straight = go straight through the "
    "next junction; lane_left = change one lane to the left; lane_right = change one lane to "
    "the right; stop = stop the car now.\n"
    'Answer with one JSON object and nothing else: {"maneuver": "<one of follow, left, right, '
    'straight, lane_left, lane_right, stop>"}.'
)
SCHEMA = {"type": "object", "properties": {"maneuver": {"type": "string", "enum": [m.value for m in MENU]}},
          "required": ["maneuver"], "additionalProperties": False}

_LIGHTS = {"r": "red", "R": "red", "y": "yellow", "Y": "yellow", "G": "green", "g": "green",
           "s": "none (stop sign)", "w": "none (all-way stop)"}
_BRANCH = {"s": "straight", "l": "left", "L": "left", "r": "right", "R": "right", "t": "u-turn"}
_BRANCH_ORDER = ("left", "straight", "right", "u-turn")


# --------------------------------------------------------------------------- settings and spec
@dataclass(frozen=True)
class LLMSettings:
    """How an LLM agent asks. ``endpoint``: the API base URL (``http://127.0.0.1:8080/v1``);
    ``key_env``: the environment variable holding the API key ("" none); ``image``: send the BEV
    raster as a PNG image part; ``format``: one of :data:`FORMATS`; ``timeout`` (s): the deadline
    of each whole request (connect, headers and body); ``seed``: sent with every request;
    ``cache_dir``: the response cache (None: answers are kept in memory only); ``offline``: the
    server was unreachable when the run began (a request not in the cache then crashes its
    episode with that reason)."""

    model: str
    endpoint: str
    key_env: str = ""
    image: bool = False
    format: str = "json_object"
    timeout: float = 60.0
    seed: int = 0
    cache_dir: Path | None = None
    offline: bool = False

    @property
    def name(self) -> str:
        """The name results are stored under: ``llm:MODEL`` (``+image`` with images)."""
        return f"{LLM_PREFIX}{self.model}" + ("+image" if self.image else "")


def parse_spec(spec: str, option: Field = Field("agents")) -> LLMSettings:
    """The settings of ``llm:MODEL@URL[?key_env=VAR&image=1&format=F&timeout=S&seed=N]``
    (InputErrors naming ``option`` and the part that is wrong)."""
    rest = spec[len(LLM_PREFIX):] if spec.startswith(LLM_PREFIX) else spec
    at = max(rest.rfind("@http://"), rest.rfind("@https://"))
    example = "use llm:MODEL@http://127.0.0.1:8080/v1"
    if at <= 0:
        raise InputError(option, spec, "an llm spec needs a model and a server URL", example)
    model, url = rest[:at], rest[at + 1:]
    if not model.strip() or any(c.isspace() for c in model):
        raise InputError(option, spec, f"model {model!r} is empty or has spaces", example)
    parts = urllib.parse.urlsplit(url)
    if not is_http(url):
        raise InputError(option, spec, f"{url!r} is not an http:// or https:// URL", example)
    query = urllib.parse.parse_qs(parts.query, keep_blank_values=True)
    endpoint = urllib.parse.urlunsplit((parts.scheme, parts.netloc, parts.path, "", ""))
    known = {"key_env", "image", "format", "timeout", "seed"}
    unknown = sorted(set(query) - known)
    if unknown:
        raise InputError(option, spec, f"unknown option {unknown[0]!r}", f"use {', '.join(sorted(known))}")
    one = {k: v[-1] for k, v in query.items()}
    s = LLMSettings(model=model, endpoint=endpoint)
    if "key_env" in one:
        s = replace(s, key_env=check_key_env(one["key_env"], option, spec))
    if "image" in one:
        if one["image"] not in ("0", "1", "true", "false"):
            raise InputError(option, spec, f"image={one['image']!r}", "use image=1 or image=0")
        s = replace(s, image=one["image"] in ("1", "true"))
    if "format" in one:
        if one["format"] not in FORMATS:
            raise InputError(option, spec, f"format={one['format']!r}", f"use one of {', '.join(FORMATS)}")
        s = replace(s, format=one["format"])
    if "timeout" in one:
        try:
            timeout = float(one["timeout"])
        except ValueError:
            timeout = math.nan
        if not (math.isfinite(timeout) and 0 < timeout <= 3600):
            raise InputError(option, spec, f"timeout={one['timeout']!r}", "use seconds between 0 and 3600")
        s = replace(s, timeout=timeout)
    if "seed" in one:
        if not re.fullmatch(r"\d{1,9}", one["seed"]):
            raise InputError(option, spec, f"seed={one['seed']!r}", "use a non-negative integer")
        s = replace(s, seed=int(one["seed"]))
    return s


def with_options(spec: str, key_env: str | None = None, image: bool = False) -> str:
    """``spec`` with ``key_env`` and ``image`` added to its URL's query (``--llm-key-env``,
    ``--llm-image``); other specs are returned as they are."""
    if not spec.startswith(LLM_PREFIX) or (not key_env and not image):
        return spec
    extra = ([f"key_env={key_env}"] if key_env else []) + (["image=1"] if image else [])
    return spec + ("&" if "?" in spec.rpartition("@")[2] else "?") + "&".join(extra)


def api_key(s: LLMSettings, option: Field = Field("agents")) -> str | None:
    """The API key from the variable ``s.key_env`` names (None when none is named); an
    InputError (naming ``option``) when the variable is not set."""
    if not s.key_env:
        return None
    key = os.environ.get(s.key_env, "")
    if not key.strip():
        raise InputError(option, s.name, f"the API key variable {s.key_env} is not set",
                         f"export {s.key_env}=... before the run, or drop key_env for a server without a key")
    return check_key_text(key.strip(), s.key_env, option, s.name)


# --------------------------------------------------------------------------- the scene
@dataclass(frozen=True)
class Scene:
    """What the model is told about the situation. ``speed`` (m/s); ``lane`` of ``lanes``
    counted from the right (0 of 0: inside a junction); ``junction_m``: m to the next junction
    with a choice (None: none within :data:`LOOK_M`) and its ``branches``; ``light``: the
    traffic light there for the ego's lane ("none" without one); ``lead_m``: m to the vehicle
    ahead in the ego's lane (None: none within :data:`LEAD_M`)."""

    speed: float
    lane: int
    lanes: int
    junction_m: float | None
    branches: tuple[str, ...]
    light: str
    lead_m: float | None

    def text(self) -> str:
        """The scene as the prompt states it (numbers rounded, so nearby moments read alike)."""
        lane = f"lane {self.lane} of {self.lanes} (counted from the right)" if self.lanes \
            else "inside a junction"
        if self.junction_m is None:
            junction = f"no junction with a choice within {LOOK_M:.0f} m"
        else:
            junction = f"next junction in {self.junction_m:.0f} m, branches: {', '.join(self.branches)}"
        lead = "none" if self.lead_m is None else f"{self.lead_m:.0f} m"
        return (f"speed {self.speed:.0f} m/s; {lane}; {junction}; traffic light: {self.light}; "
                f"vehicle ahead: {lead}")


def user_message(instruction: str, scene: Scene) -> str:
    said = json.dumps(instruction, ensure_ascii=False)
    return f"Instruction: {said}\nScene: {scene.text()}.\nWhich maneuver?"


def build_request(s: LLMSettings, instruction: str, scene: Scene, png: bytes | None = None) -> dict:
    """The chat-completions request body for one question."""
    text = user_message(instruction, scene)
    content: Any = text
    if png is not None:
        content = [{"type": "text", "text": text},
                   {"type": "image_url", "image_url": {"url": "data:image/png;base64,"
                                                       + base64.b64encode(png).decode("ascii")}}]
    body: dict[str, Any] = {
        "model": s.model,
        "messages": [{"role": "system", "content": SYSTEM}, {"role": "user", "content": content}],
        "temperature": 0,
        "seed": s.seed,
        "max_tokens": MAX_TOKENS,
    }
    return with_format(body, s.format, "maneuver", SCHEMA)


def with_format(body: dict, fmt: str, name: str, schema: dict) -> dict:
    """``body`` with the structured-output ``response_format`` of ``fmt`` (one of
    :data:`FORMATS`; ``none``: none) for JSON ``schema`` named ``name``."""
    if fmt == "json_object":
        body["response_format"] = {"type": "json_object", "schema": schema}
    elif fmt == "json_schema":
        body["response_format"] = {"type": "json_schema",
                                   "json_schema": {"name": name, "strict": True, "schema": schema}}
    return body


_FENCE = re.compile(r"```[ \t]*(?:json|JSON)?[ \t]*\r?\n?(.*?)```", re.DOTALL)


def parse_answer(content: str) -> Intent:
    """The maneuver of an answer text: a JSON object (bare or in a ```json fence) whose
    ``maneuver`` is one of :data:`MENU`; :class:`Invalid` saying what is wrong otherwise."""
    text = content.strip()
    if not text:
        raise Invalid(["answer is empty"])
    try:
        obj = json.loads(text)
    except (ValueError, RecursionError):
        fenced = _FENCE.search(text)
        try:
            obj = json.loads(fenced.group(1)) if fenced else None
        except (ValueError, RecursionError):
            obj = None
        if obj is None:
            raise Invalid(["answer is not JSON"]) from None
    if not isinstance(obj, dict) or "maneuver" not in obj:
        raise Invalid(['answer is not a JSON object with key "maneuver"'])
    value = obj["maneuver"]
    menu = {m.value: m for m in MENU}
    if not isinstance(value, str) or value.strip().lower() not in menu:
        raise Invalid([f"maneuver {str(value)[:40]!r} is not on the menu"])
    return menu[value.strip().lower()]


@dataclass(frozen=True)
class Answer:
    """A model's answer to one request: the ``maneuver`` (follow when invalid), ``valid``, the
    answer ``text`` ("" when the model said nothing) and the ``problem`` of an invalid one."""

    maneuver: Intent
    valid: bool
    text: str
    problem: str = ""


def answer_of(record: dict) -> Answer:
    """The :class:`Answer` of a cache record (its ``content``: the model's answer text)."""
    content = str(record["content"])
    try:
        return Answer(parse_answer(content), True, content)
    except Invalid as err:
        return Answer(Intent.FOLLOW, False, content, err.summary)


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

    def ask(self, body: dict) -> tuple[str, Answer]:
        """(cache key, answer) of the request ``body``."""
        key, rec = self.record(body)
        return key, answer_of(rec)

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
    docstring). ``calls``: the episode's exchanges so far (:class:`icrsumo.types.ModelCall`)."""

    def __init__(self, settings: LLMSettings) -> None:
        super().__init__()
        self.settings = settings
        self.name = settings.name
        self.asker = Asker(settings, api_key(settings))
        self.calls: list[ModelCall] = []
        self._asked: set[tuple[int, str]] = set()
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
        changed = obs.instruction_id != self._instr_id
        super().observe(obs)   # asks when the instruction changed
        w = obs.world
        if w is None or obs.instruction_id < 0 or not w.lane or w.lane.startswith(":"):
            return
        edge = _lane_edge(w.lane)
        options = self._options(edge)
        ahead = self.net.lane_length.get(w.lane, 0.0) - w.lane_pos
        if len(options) < 2 or ahead > ASK_M or (obs.instruction_id, edge) in self._asked:
            return
        self._asked.add((obs.instruction_id, edge))
        if changed:   # just asked, with this junction in the scene
            return
        intent = self._ask(obs, "junction")
        if intent != self.intent:
            self.intent = intent
            self._decided.pop(edge, None)
        self._spent = None   # the model decided for this junction

    # ---- asking
    def _ask(self, obs: Observation, at: str) -> Intent:
        scene = self.scene(obs)
        png = self._png(obs) if self.settings.image else None
        body = build_request(self.settings, obs.instruction, scene, png)
        key, answer = self.asker.ask(body)
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
            edge, idx = _lane_edge(w.lane), _lane_index(w.lane)
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
        from ..render import png_bytes, to_rgb

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
