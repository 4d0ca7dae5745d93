"""Instruction files (``icrsumo-instructions/1``): one JSON file per route holding the baseline
sequence and every variant sequence. See the README for the format."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from ..fsio import read_json_doc
from ..types import Instruction, InstructionSet, Intent, Maneuver, Notice
from ..vocab import Family
from .intent import classify_intent

FORMAT = "icrsumo-instructions/1"


def instruction_dict(ins: Instruction) -> dict:
    d = asdict(ins)
    d["intent"] = ins.intent.value
    d["classified"] = classify_intent(ins.text).value
    return d


def route_document(baseline: InstructionSet, variants: list[InstructionSet],
                   maneuvers: list[Maneuver], meta: dict) -> dict:
    """The JSON document of one route: ``meta`` keys first, then maneuvers, notices, sets."""
    return {
        "format": FORMAT,
        "route_id": baseline.route_id,
        **meta,
        "route_seed": baseline.seed,
        "maneuvers": [dict(asdict(m), intent=m.intent.value) for m in maneuvers],
        "notices": [dict(asdict(n), intent=n.intent.value) for n in baseline.notices],
        "sets": [
            {"family": s.family, "k": s.k, "seed": s.seed,
             "instructions": [instruction_dict(i) for i in s.instructions]}
            for s in (baseline, *variants)
        ],
    }


def _instruction(d: dict) -> Instruction:
    return Instruction(
        id=int(d["id"]), trigger=float(d["trigger"]), text=str(d["text"]), intent=Intent(d["intent"]),
        type=str(d["type"]), distance=None if d.get("distance") is None else float(d["distance"]),
        maneuver_pos=None if d.get("maneuver_pos") is None else float(d["maneuver_pos"]),
        junction=d.get("junction", ""), template=d.get("template", ""), source=d.get("source", ""),
    )


def read_instruction_sets(path: Path) -> list[InstructionSet]:
    """All sequences of a route file: the baseline first, then variants in file order."""
    doc = read_json_doc(path, FORMAT, "instruction file", "run icrsumo generate")
    notices = tuple(
        Notice(id=int(n["id"]), trigger=float(n["trigger"]), end=float(n["end"]), text=n["text"],
               type=n["type"], intent=Intent(n["intent"]))
        for n in doc.get("notices", [])
    )
    return [
        InstructionSet(route_id=doc["route_id"], family=Family(s["family"]), k=int(s["k"]),
                       seed=int(s["seed"]), instructions=tuple(_instruction(i) for i in s["instructions"]),
                       notices=notices)
        for s in doc["sets"]
    ]
