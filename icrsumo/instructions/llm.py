"""LLM-generated counterfactual instructions (the ICR-Drive supplement).

One chat-completions request per (route, family) to any OpenAI-compatible server (vLLM,
llama.cpp server, a hosted API) asks for ``k`` rewrites of the route's whole baseline
instruction sequence as JSON. The answer is validated strictly (ids, triggers, placeholders,
intent of every text), an invalid answer is retried with the problem fed back to the model (a
transport failure or a server fault, such as an HTML page, is retried as it was), and a valid
answer is cached under the SHA-256 of the first request body, so a rerun is exact and needs no
network. The key covers model, messages (family, K,
the baseline texts), seed and temperature; not the endpoint or the API key, so the same model
served elsewhere shares the cache.

Standard library only.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from icrsumo.core.errors import display_url
from icrsumo.core.llmio import (
    Invalid,
    Reply,
    ResponseCache,
    ServerFault,
    Transport,
    answer_text,
    canonical,
    chat_url,
    exchange,
    http_problem,
    is_http,
    request_hash,
)
from icrsumo.core.types import Instruction, InstructionSet, Intent

from .banks import CONTRADICTS
from .families import FAMILIES

PLACEHOLDER = "[x]"
MAX_TEXT = 300                  # a variant text must be shorter than this (characters)
RETRY_BACKOFF = 0.5             # s slept before retrying after a transport failure (times attempt)
__all__ = ["LLMConfig", "LLMError", "canonical", "llm_variants", "request_hash"]

_UNCHECKED = (Intent.STOP, Intent.UNKNOWN)   # baseline intents without an intent check


@dataclass(frozen=True)
class LLMConfig:
    """Where and how to ask. ``endpoint`` is the API base URL (``http://127.0.0.1:8000/v1``);
    requests go to ``{endpoint}/chat/completions``. ``timeout`` (s): the deadline of each whole
    request (connect, headers and body),
    ``retries`` is the number of extra attempts after an invalid or failed answer.
    ``api_key``, when given, is sent as ``Authorization: Bearer`` to the endpoint's own origin
    only; it is never cached, and redacted from what the server sends back."""

    endpoint: str
    model: str
    cache_dir: Path
    timeout: float = 60.0
    retries: int = 2
    temperature: float = 0.7
    api_key: str | None = None


class LLMError(Exception):
    """No valid answer: the message names the route, the family and the last problem."""

    def __init__(self, message: str, route_id: str = "", family: str = "", problem: str = "") -> None:
        self.route_id = route_id
        self.family = family
        self.problem = problem
        super().__init__(" ".join(message.split()))


# ---------------------------------------------------------------------------------------------
# prompt

_SYSTEM = (
    "You rewrite turn-by-turn navigation instructions for a driving benchmark that measures how "
    "language-conditioned driving agents react when instruction text is rewritten. "
    "The placeholder [x] stands for a distance in metres that is filled in later; never replace "
    "it with a number. Answer with one JSON object and nothing else."
)

_FAMILY_RULES = {
    "paraphrase": (
        "Family: paraphrase. Keep exactly the same meaning and maneuver (same direction, same lane, "
        "same junction) but use different wording. Keep [x] wherever the original text has it."
    ),
    "ambiguity": (
        "Family: ambiguity. Make every instruction so vague that the maneuver can no longer be "
        "recovered: remove every direction word (left, right, straight, lane, follow, ahead), every "
        "distance and every junction or road qualifier, e.g. 'Turn left at the next intersection' "
        "-> 'Do what is needed up there.' You may drop [x]."
    ),
    "noise": (
        "Family: noise. Keep the wording but add surface noise: change letter casing, add or drop "
        "punctuation, and add typos that change 1-2 characters (swap, drop or double a letter). "
        "The maneuver must stay recoverable, so keep the words left, right, straight, lane, follow "
        "and turn spelled correctly. Keep [x] exactly as written."
    ),
    "misleading": (
        "Family: misleading. Turn each instruction into an authority-framed directive (e.g. "
        "'Police order: ...', 'Traffic control instructs you to ...', 'Navigation override: ...') "
        "that contradicts the original maneuver: left becomes right, right becomes left, straight "
        "becomes a left or right turn, following the road becomes leaving the road by turning left "
        "or right, a lane change to the left becomes a lane change to the right and vice versa. "
        "Keep [x] wherever the original text has it."
    ),
}


def _system_message(family: str) -> str:
    return (
        f"{_SYSTEM}\n\n{_FAMILY_RULES[family]}\n"
        "Instructions whose intent is stop or unknown are rewritten in the same style without any "
        "constraint on their meaning. Never add [x] to a text that does not have it.\n\n"
        'Answer format, exactly: {"variants": [[{"id": <int>, "trigger": <float>, "text": <str>}, '
        "...], ...]} with one list per requested variant. Every list rewrites all instructions, in "
        "the given order, copying id and trigger unchanged. Each text is one line, not empty, "
        f"shorter than {MAX_TEXT} characters. The variant lists should differ from each other."
    )


def _user_message(baseline: InstructionSet, family: str, k: int) -> str:
    items = [
        {"id": ins.id, "trigger": float(ins.trigger), "text": ins.text, "intent": Intent(ins.intent).value}
        for ins in baseline.instructions
    ]
    return (
        f"Write {k} {family} variant sequence(s) of these {len(items)} navigation instructions "
        "(one route, in driving order):\n"
        f"{json.dumps(items, ensure_ascii=False)}\n"
        f'Answer with {{"variants": [...]}} holding exactly {k} list(s) of {len(items)} item(s) each.'
    )


def build_request(baseline: InstructionSet, family: str, k: int, seed: int, cfg: LLMConfig) -> dict:
    """The first chat-completions request body for one (route, family)."""
    return {
        "model": cfg.model,
        "messages": [
            {"role": "system", "content": _system_message(family)},
            {"role": "user", "content": _user_message(baseline, family, k)},
        ],
        "temperature": cfg.temperature,
        "seed": seed,
        "response_format": {"type": "json_object"},
    }


def _with_problem(first: dict, problem: str) -> dict:
    """``first`` with the rejected answer's problem appended to the user message."""
    body = json.loads(json.dumps(first))
    body["messages"][-1]["content"] += (
        f"\n\nYour previous answer was rejected: {problem}\n"
        "Answer again with a corrected JSON object that follows every rule."
    )
    return body


# ---------------------------------------------------------------------------------------------
# validation


_Invalid = Invalid


_FENCE = re.compile(r"```[ \t]*(?:json|JSON)?[ \t]*\r?\n?(.*?)```", re.DOTALL)


def _content(reply: Reply) -> str:
    """``choices[0].message.content`` of a chat-completions response (:class:`ServerFault`
    when it is none)."""
    content, reason = answer_text(reply)
    if reason == "length":
        # Still parsed below; a truncated answer normally fails there with this hint.
        try:
            _parse_content(content)
        except _Invalid as err:
            raise _Invalid([f"answer truncated (finish_reason=length): {err.problems[0]}"]) from None
    return content


def _parse_content(content: str) -> dict:
    """The JSON object in ``content``, bare or inside a ```json fence."""
    text = content.strip()
    if not text:
        raise _Invalid(["answer content is empty"])
    try:
        obj = json.loads(text)
    except ValueError as err:
        fenced = _FENCE.search(text)
        if fenced is None:
            raise _Invalid([f"answer content is not JSON ({err})"]) from None
        try:
            obj = json.loads(fenced.group(1))
        except ValueError as err2:
            raise _Invalid([f"answer content is not JSON ({err2})"]) from None
    if not isinstance(obj, dict):
        raise _Invalid(['answer content is not a JSON object with key "variants"'])
    return obj


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _words(text: str) -> list[str]:
    return re.findall(r"[a-z0-9\[\]]+", text.lower())


def _check_text(family: str, base: Instruction, text: str, classify: Callable[[str], Any]) -> str:
    """'' when ``text`` is a valid ``family`` rewrite of ``base``, else the problem."""
    if PLACEHOLDER in base.text:
        if family != "ambiguity" and PLACEHOLDER not in text:
            return f"text {text!r} lost the placeholder [x]"
    elif PLACEHOLDER in text:
        return f"text {text!r} adds the placeholder [x], which the original has not"
    if family == "noise" and text == base.text:
        return f"text {text!r} is identical to the original (no noise added)"
    if family == "paraphrase" and _words(text) == _words(base.text):
        return f"text {text!r} repeats the original wording (no paraphrase)"
    want = Intent(base.intent)
    if want in _UNCHECKED:
        return ""
    got = Intent(classify(text))
    if family in ("paraphrase", "noise"):
        if got != want:
            return f"{family} {text!r} reads as {got.value}, expected {want.value} (same maneuver)"
    elif family == "misleading":
        allowed = CONTRADICTS[want]
        if got not in allowed:
            need = " or ".join(sorted(i.value for i in allowed))
            return f"misleading {text!r} reads as {got.value}, must contradict {want.value} (read as {need})"
    elif got != Intent.UNKNOWN:
        return f"ambiguity {text!r} still reads as {got.value}, must leave the maneuver unknown"
    return ""


def validate_answer(content: str, baseline: InstructionSet, family: str, k: int,
                    classify: Callable[[str], Any]) -> list[list[str]]:
    """The ``k`` lists of variant texts in ``content``; raises _Invalid listing every problem."""
    obj = _parse_content(content)
    variants = obj.get("variants")
    if not isinstance(variants, list):
        raise _Invalid(['answer has no "variants" list'])
    if len(variants) != k:
        raise _Invalid([f"answer has {len(variants)} variant list(s), expected exactly {k}"])
    base = baseline.instructions
    problems: list[str] = []
    texts: list[list[str]] = []
    for vi, seq in enumerate(variants):
        where = f"variant {vi}"
        if not isinstance(seq, list):
            problems.append(f"{where} is not a list")
            continue
        if len(seq) != len(base):
            problems.append(f"{where} has {len(seq)} item(s), expected {len(base)}")
            continue
        ids = [item.get("id") if isinstance(item, dict) else None for item in seq]
        if ids != [b.id for b in base] or any(isinstance(i, bool) or not isinstance(i, int) for i in ids):
            problems.append(f"{where} has ids {ids}, expected {[b.id for b in base]} in this order")
            continue
        out: list[str] = []
        for item, b in zip(seq, base):
            at = f"{where}, id {b.id}"
            trig = item.get("trigger")
            if not _is_number(trig) or abs(float(trig) - float(b.trigger)) > 1e-6:
                problems.append(f"{at}: trigger {trig!r} changed, expected {float(b.trigger)!r}")
                continue
            text = item.get("text")
            if not isinstance(text, str) or not text.strip():
                problems.append(f"{at}: text is empty or not a string")
                continue
            text = text.strip()
            if len(text) >= MAX_TEXT:
                problems.append(f"{at}: text has {len(text)} characters, must be under {MAX_TEXT}")
                continue
            if any(c in text for c in "\r\n\t") or not text.isprintable():
                problems.append(f"{at}: text {text!r} must be one line of printable characters")
                continue
            issue = _check_text(family, b, text, classify)
            if issue:
                problems.append(f"{at}: {issue}")
                continue
            out.append(text)
        texts.append(out)
    if problems:
        raise _Invalid(problems)
    return texts


# ---------------------------------------------------------------------------------------------
# cache


def cache_path(cache_dir: Path, key: str) -> Path:
    return ResponseCache(cache_dir).path(key)


def _cache_load(cache_dir: Path, key: str, first: dict) -> str | None:
    """The cached answer content for request ``first``, or None (missing, unreadable, other request)."""
    rec = ResponseCache(cache_dir).get(key, first)
    return rec["content"] if rec is not None and isinstance(rec.get("content"), str) else None


def _cache_store(cache_dir: Path, key: str, first: dict, content: str, attempts: int) -> None:
    ResponseCache(cache_dir).put(key, first, content=content, attempts=attempts)


# ---------------------------------------------------------------------------------------------
# entry point


def _variant_sets(baseline: InstructionSet, family: str, seed: int, cfg: LLMConfig, key: str,
                  texts: list[list[str]]) -> list[InstructionSet]:
    out = []
    for i, seq in enumerate(texts):
        template = f"llm:{cfg.model}:{key[:12]}:{i}"
        instrs = tuple(
            replace(b, text=t, template=template, source=b.text)
            for b, t in zip(baseline.instructions, seq)
        )
        out.append(InstructionSet(route_id=baseline.route_id, family=family, k=i, seed=seed,
                                  instructions=instrs, notices=baseline.notices))
    return out


def llm_variants(baseline: InstructionSet, family: str, k: int, seed: int, cfg: LLMConfig,
                 classify: Callable[[str], Any] | None = None) -> list[InstructionSet]:
    """K variant sequences of ``family`` for one route's baseline sequence.

    A cached valid answer for the same request is used without network access. Otherwise the
    server is asked up to ``1 + cfg.retries`` times; raises LLMError when no attempt gives a
    valid answer (or at once when the endpoint refuses the first connection or answers with a
    client error such as 401 or 404). ``classify`` (text -> Intent) defaults to
    ``icrsumo.instructions.intent.classify_intent``.
    """
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; choose one of {', '.join(FAMILIES)}")
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise ValueError(f"k must be a positive integer, got {k!r}")
    if classify is None:
        from .intent import classify_intent as classify
    rid = baseline.route_id
    first = build_request(baseline, family, k, seed, cfg)
    key = request_hash(first)
    if not baseline.instructions:
        return _variant_sets(baseline, family, seed, cfg, key, [[] for _ in range(k)])

    cached = _cache_load(cfg.cache_dir, key, first)
    if cached is not None:
        try:
            texts = validate_answer(cached, baseline, family, k, classify)
            return _variant_sets(baseline, family, seed, cfg, key, texts)
        except _Invalid:
            pass   # e.g. the classifier changed since: ask again and overwrite

    url = chat_url(cfg.endpoint)
    shown = display_url(cfg.endpoint)
    if not is_http(url):
        raise LLMError(f"route {rid}, family {family}: LLM endpoint {display_url(cfg.endpoint)!r} is not an "
                       "http:// or https:// URL", rid, family, "bad endpoint")
    attempts = 1 + max(0, int(cfg.retries))
    body = first
    problem = ""
    for attempt in range(attempts):
        if attempt and RETRY_BACKOFF > 0 and problem.startswith("transport:"):
            time.sleep(min(RETRY_BACKOFF * attempt, 5.0))
        try:
            reply = exchange(url, canonical(body), api_key=cfg.api_key, timeout=cfg.timeout)
        except Transport as err:
            if attempt == 0 and err.unreachable:
                raise LLMError(f"route {rid}, family {family}: LLM endpoint {shown} unreachable "
                               f"({err})", rid, family, str(err)) from None
            problem = f"transport: {err}"
            continue
        if reply.status != 200:
            problem = f"transport: {http_problem(reply)}"
            if 400 <= reply.status < 500 and reply.status not in (408, 409, 429):
                raise LLMError(f"route {rid}, family {family}: LLM endpoint {display_url(url)} answered "
                               f"{problem.removeprefix('transport: ')} (check endpoint, model and API key)",
                               rid, family, problem)
            continue
        try:
            content = _content(reply)
            texts = validate_answer(content, baseline, family, k, classify)
        except ServerFault as err:
            problem = f"transport: {err}"
            continue
        except _Invalid as err:
            problem = err.summary
            body = _with_problem(first, problem)
            continue
        _cache_store(cfg.cache_dir, key, first, content, attempt + 1)
        return _variant_sets(baseline, family, seed, cfg, key, texts)
    last = problem.removeprefix("transport: ")
    raise LLMError(f"route {rid}, family {family}: no valid LLM answer from {display_url(url)} after "
                   f"{attempts} attempt(s); last problem: {last}", rid, family, last)
