"""Instruction files (``icrsumo-instructions/1``): one JSON file per route holding the baseline
sequence and every variant sequence. See the README for the format."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from icrsumo.core.doccheck import DocChecker
from icrsumo.core.fsio import read_json_doc
from icrsumo.core.types import Instruction, InstructionSet, Intent, Maneuver, Notice
from icrsumo.core.vocab import Family

from .intent import classify_intent

FORMAT = "icrsumo-instructions/1"


def instruction_dict(ins: Instruction) -> dict:
    d = asdict(ins)
    d["intent"] = ins.intent.value
    d["classified"] = classify_intent(ins.text).value
    return d


def _notices(notices: tuple[Notice, ...]) -> list[dict]:
    return [dict(asdict(n), intent=n.intent.value) for n in notices]


def route_document(baseline: InstructionSet, variants: list[InstructionSet],
                   maneuvers: list[Maneuver], meta: dict) -> dict:
    """The JSON document of one route: ``meta`` keys first, then maneuvers, notices (the
    baseline's), sets; a set whose notices are not the baseline's (the ``notice`` family) holds
    its own."""
    return {
        "format": FORMAT,
        "route_id": baseline.route_id,
        **meta,
        "route_seed": baseline.seed,
        "maneuvers": [dict(asdict(m), intent=m.intent.value) for m in maneuvers],
        "notices": _notices(baseline.notices),
        "sets": [
            {"family": s.family, "k": s.k, "seed": s.seed,
             "instructions": [instruction_dict(i) for i in s.instructions],
             **({"notices": _notices(s.notices)} if s.notices != baseline.notices else {})}
            for s in (baseline, *variants)
        ],
    }


_FIX = "run icrsumo generate again"
#: Maneuver.kind values
MANEUVER_KINDS = ("turn_left", "turn_right", "straight", "u_turn", "roundabout", "highway_enter",
                  "highway_exit", "lane_change_left", "lane_change_right", "follow")


def _opt_number(c: DocChecker, d: dict, key: str, place: str) -> float | None:
    v = d.get(key)
    return None if v is None else c.number(v, f"{place}.{key}", 0.0)


def _instruction(c: DocChecker, d: object, place: str) -> Instruction:
    d = c.obj(d, place)
    if "classified" in d:
        c.choice(d["classified"], f"{place}.classified", Intent, "intent")
    return Instruction(
        id=c.integer(c.key(d, "id", place), f"{place}.id", 0),
        trigger=c.number(c.key(d, "trigger", place), f"{place}.trigger", 0.0),
        text=c.string(c.key(d, "text", place), f"{place}.text"),
        intent=c.member(c.key(d, "intent", place), f"{place}.intent", Intent, "intent"),
        type=c.string(c.key(d, "type", place), f"{place}.type"),
        distance=_opt_number(c, d, "distance", place),
        maneuver_pos=_opt_number(c, d, "maneuver_pos", place),
        junction=c.string(d.get("junction", ""), f"{place}.junction"),
        template=c.string(d.get("template", ""), f"{place}.template"),
        source=c.string(d.get("source", ""), f"{place}.source"),
    )


def _notice(c: DocChecker, n: object, place: str) -> Notice:
    n = c.obj(n, place)
    trigger = c.number(c.key(n, "trigger", place), f"{place}.trigger", 0.0)
    end = c.number(c.key(n, "end", place), f"{place}.end", trigger)
    return Notice(
        id=c.integer(c.key(n, "id", place), f"{place}.id", 0), trigger=trigger, end=end,
        text=c.string(c.key(n, "text", place), f"{place}.text"),
        type=c.string(c.key(n, "type", place), f"{place}.type"),
        intent=c.member(n.get("intent", "unknown"), f"{place}.intent", Intent, "intent"),
    )


def _check_maneuver(c: DocChecker, m: object, place: str) -> None:
    m = c.obj(m, place)
    c.choice(c.key(m, "kind", place), f"{place}.kind", MANEUVER_KINDS, "maneuver kind")
    c.number(c.key(m, "pos", place), f"{place}.pos")
    c.choice(c.key(m, "intent", place), f"{place}.intent", Intent, "intent")
    for k in ("junction", "junction_id"):
        if k in m:
            c.string(m[k], f"{place}.{k}")
    for k in ("exit", "lanes"):
        if k in m:
            c.integer(m[k], f"{place}.{k}", 0)
    for k in ("length", "end"):
        if k in m:
            c.number(m[k], f"{place}.{k}")


def read_instruction_sets(path: Path) -> list[InstructionSet]:
    """All sequences of a route file: the baseline first, then variants in file order. Every
    problem (wrong types, unknown family or intent, missing keys, triggers out of order, an
    instruction id twice in a set, no baseline first, a (family, k) twice) is an InputError
    naming the file and the key."""
    return read_route_file(path)[0]


def read_route_file(path: Path) -> tuple[list[InstructionSet], tuple[Maneuver, ...]]:
    """The sequences of a route file (as :func:`read_instruction_sets`) and the route's
    maneuvers recorded in it (route order), from one reading of the file."""
    doc = read_json_doc(path, FORMAT, "instruction file", "run icrsumo generate")
    c = DocChecker(path, _FIX)
    route_id = c.string(c.key(doc, "route_id"), "route_id", nonempty=True, limit=200)
    maneuvers = []
    for i, m in enumerate(c.lst(doc.get("maneuvers", []), "maneuvers")):
        _check_maneuver(c, m, f"maneuvers[{i}]")
        fields = {k: m[k] for k in ("junction", "junction_id", "exit", "length", "end", "lanes") if k in m}
        maneuvers.append(Maneuver(kind=m["kind"], pos=float(m["pos"]), intent=Intent(m["intent"]), **fields))
    notices = tuple(_notice(c, n, f"notices[{i}]")
                    for i, n in enumerate(c.lst(doc.get("notices", []), "notices")))
    out: list[InstructionSet] = []
    seen: set[tuple[str, int]] = set()
    for si, s in enumerate(c.lst(c.key(doc, "sets"), "sets", 1)):
        place = f"sets[{si}]"
        s = c.obj(s, place)
        family = c.member(c.key(s, "family", place), f"{place}.family", Family, "family")
        k = c.integer(c.key(s, "k", place), f"{place}.k", 0)
        if (si == 0) != (family == Family.BASELINE):
            raise c.fail(f"{place}.family", "the first set must be the baseline" if si == 0
                         else "only the first set may be the baseline")
        if (family, k) in seen:
            raise c.fail(place, f"a second set of family {family} with k={k}")
        seen.add((family, k))
        seed = c.integer(c.key(s, "seed", place), f"{place}.seed")
        items = c.lst(c.key(s, "instructions", place), f"{place}.instructions")
        instructions = tuple(_instruction(c, d, f"{place}.instructions[{i}]") for i, d in enumerate(items))
        ids = [ins.id for ins in instructions]
        if len(set(ids)) < len(ids):
            i = next(i for i, v in enumerate(ids) if v in ids[:i])
            raise c.fail(f"{place}.instructions[{i}].id", f"a second instruction with id {ids[i]}",
                         "give every instruction of a set its own id")
        for i in range(1, len(instructions)):
            if instructions[i].trigger < instructions[i - 1].trigger:
                raise c.fail(f"{place}.instructions[{i}].trigger",
                             f"trigger {instructions[i].trigger:g} comes before the previous one "
                             f"({instructions[i - 1].trigger:g})", "list instructions by trigger")
        own = notices if "notices" not in s else tuple(
            _notice(c, n, f"{place}.notices[{i}]")
            for i, n in enumerate(c.lst(s["notices"], f"{place}.notices")))
        out.append(InstructionSet(route_id=route_id, family=family, k=k, seed=seed,
                                  instructions=instructions, notices=own))
    return out, tuple(maneuvers)


def skipped_families(folder: Path) -> dict[str, dict[str, str]]:
    """Route id -> {family: why} of the delivery families a generated folder (its
    ``index.json``, ``skipped``) could not build for the route; {} when there is none (or no
    index)."""
    path = Path(folder) / "index.json"
    if not path.is_file():
        return {}
    doc = read_json_doc(path, FORMAT.replace("instructions", "instruction-index"), "instruction index",
                        "run icrsumo generate")
    c = DocChecker(path, _FIX)
    out: dict[str, dict[str, str]] = {}
    for i, row in enumerate(c.lst(doc.get("skipped", []), "skipped")):
        row = c.obj(row, f"skipped[{i}]")
        rid, fam, why = (c.string(c.key(row, key, f"skipped[{i}]"), f"skipped[{i}].{key}")
                         for key in ("route_id", "family", "why"))
        out.setdefault(rid, {})[fam] = why
    return out
