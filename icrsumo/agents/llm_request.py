"""What the LLM agent (:mod:`icrsumo.agents.llm`) asks and how it reads the answer, no network:
its settings (:func:`parse_spec` of ``llm:MODEL@URL[?...]``), the API key, the :class:`Scene`,
the chat-completions request body (:func:`build_request`; its bytes are the response cache's key)
and the answer read back (:func:`parse_answer`, :class:`Answer`)."""

from __future__ import annotations

import base64
import json
import math
import os
import re
import urllib.parse
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from icrsumo.core.errors import Field, InputError, check_key_env, check_key_text
from icrsumo.core.llmio import Invalid, is_http
from icrsumo.core.types import Intent

#: the spec prefix (:data:`icrsumo.agents.registry.LLM_PREFIX` dispatches to :mod:`icrsumo.agents.llm`)
LLM_PREFIX = "llm:"

#: the maneuvers a model may answer (Intent values)
MENU: tuple[Intent, ...] = (Intent.FOLLOW, Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT,
                            Intent.LANE_LEFT, Intent.LANE_RIGHT, Intent.STOP)
#: structured-output request styles
FORMATS = ("json_object", "json_schema", "none")
#: m ahead searched for the next junction with a choice (along the road's only continuation)
LOOK_M = 200.0
#: tokens an answer may have (the JSON answer needs about 10)
MAX_TOKENS = 32
#: changes whenever the prompt's wording changes (part of the agent's fingerprint)
PROMPT_VERSION = "1"

_MANEUVERS = (
    "Maneuvers: follow = keep following the current road; left = turn left at the next "
    "junction; right = turn right at the next junction; straight = go straight through the "
    "next junction; lane_left = change one lane to the left; lane_right = change one lane to "
    "the right; stop = stop the car now"
)
SYSTEM = (
    "You are the language module of a self-driving car. The car steers, keeps its lane, keeps "
    "its distance and obeys traffic lights by itself. Your only job is to read the instruction "
    "it was given and choose the maneuver to make now or at the next junction.\n"
    f"{_MANEUVERS}.\n"
    'Answer with one JSON object and nothing else: {"maneuver": "<one of follow, left, right, '
    'straight, lane_left, lane_right, stop>"}.'
)
SCHEMA = {"type": "object", "properties": {"maneuver": {"type": "string", "enum": [m.value for m in MENU]}},
          "required": ["maneuver"], "additionalProperties": False}
#: the answer that asks the navigator for clarification (offered only when the run has asking on)
ASK = "ask"
#: the system prompt and schema with asking on: :data:`SYSTEM` and :data:`SCHEMA` with :data:`ASK`
SYSTEM_ASKING = SYSTEM.replace(
    f"{_MANEUVERS}.", f"{_MANEUVERS}; ask = the instruction does not say which maneuver: ask the "
    "navigator, who answers with the next maneuver in a moment.").replace("stop>", "stop, ask>")
SCHEMA_ASKING = {**SCHEMA,
                 "properties": {"maneuver": {"type": "string", "enum": [*(m.value for m in MENU), ASK]}}}


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


def build_request(s: LLMSettings, instruction: str, scene: Scene, png: bytes | None = None,
                  asking: bool = False) -> dict:
    """The chat-completions request body for one question; ``asking``: the model may answer
    :data:`ASK` (:data:`SYSTEM_ASKING`, :data:`SCHEMA_ASKING`)."""
    text = user_message(instruction, scene)
    content: Any = text
    if png is not None:
        content = [{"type": "text", "text": text},
                   {"type": "image_url", "image_url": {"url": "data:image/png;base64,"
                                                       + base64.b64encode(png).decode("ascii")}}]
    body: dict[str, Any] = {
        "model": s.model,
        "messages": [{"role": "system", "content": SYSTEM_ASKING if asking else SYSTEM},
                     {"role": "user", "content": content}],
        "temperature": 0,
        "seed": s.seed,
        "max_tokens": MAX_TOKENS,
    }
    return with_format(body, s.format, "maneuver", SCHEMA_ASKING if asking else SCHEMA)


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


def parse_answer(content: str, asking: bool = False) -> Intent:
    """The maneuver of an answer text: a JSON object (bare or in a ```json fence) whose
    ``maneuver`` is one of :data:`MENU` (or, with ``asking``, :data:`ASK`: the intent is then
    unknown, and the agent asks the navigator); :class:`Invalid` saying what is wrong otherwise."""
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
    menu = {m.value: m for m in MENU} | ({ASK: Intent.UNKNOWN} if asking else {})
    if not isinstance(value, str) or value.strip().lower() not in menu:
        raise Invalid([f"maneuver {str(value)[:40]!r} is not on the menu"])
    return menu[value.strip().lower()]


@dataclass(frozen=True)
class Answer:
    """A model's answer to one request: the ``maneuver`` (follow when invalid; unknown for
    :data:`ASK`), ``valid``, the answer ``text`` ("" when the model said nothing) and the
    ``problem`` of an invalid one."""

    maneuver: Intent
    valid: bool
    text: str
    problem: str = ""


def answer_of(record: dict, asking: bool = False) -> Answer:
    """The :class:`Answer` of a cache record (its ``content``: the model's answer text);
    ``asking``: :data:`ASK` is an answer."""
    content = str(record["content"])
    try:
        return Answer(parse_answer(content, asking), True, content)
    except Invalid as err:
        return Answer(Intent.FOLLOW, False, content, err.summary)
