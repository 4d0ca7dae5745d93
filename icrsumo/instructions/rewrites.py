"""The search space of ``icrsumo attack``: rewrites of one baseline instruction (pure).

Goal-preserving rewrites of an instruction with intent τ (its meaning kept: the classifier
still returns τ, and ``[x]`` is kept exactly when the baseline text has it):

- a paraphrase bank entry of τ (``templates/paraphrase.json``), junction filled (its id);
- a noise operation of ``templates/noise.json`` applied to the baseline text (its id);
- a noise operation applied to a paraphrase (``<paraphrase id>+<operation id>``).

With ``misleading=True`` (``--constraint misleading``) the misleading bank's entries of τ
(another branch, authority-framed; their ids) join the space. Instructions whose intent is stop
or unknown have no rewrites. Noise draws come from a Generator seeded by (seed, route,
instruction id, operation), so a pool is the same in every run.
"""

from __future__ import annotations

import zlib

import numpy as np

from icrsumo.core.types import Instruction, Intent

from .banks import CONTRADICTS, Banks, fill
from .intent import classify_intent
from .noise import apply_ops


def _noisy(text: str, op_id: str, ops: tuple[str, ...], seed: int, route_id: str, iid: int) -> str:
    rng = np.random.default_rng([seed, zlib.crc32(route_id.encode()), iid, zlib.crc32(op_id.encode())])
    return apply_ops(text, ops, rng)


def rewrite_pool(
    instr: Instruction, banks: Banks, seed: int, route_id: str, misleading: bool = False
) -> tuple[tuple[str, str], ...]:
    """(text, template id) of every admissible rewrite of ``instr`` (a baseline instruction),
    in a fixed order, without duplicate texts and without the baseline text itself."""
    tau = instr.intent
    if tau in (Intent.STOP, Intent.UNKNOWN):
        return ()
    has_x = "[x]" in instr.text
    form = "distance" if has_x else "plain"
    bases = [(instr.text, "")]
    if tau in banks.paraphrase:
        bases += [(fill(e.text, instr.junction), e.id) for e in banks.paraphrase[tau][form]]
    out: dict[str, str] = {}

    def keep(text: str, tid: str, want: frozenset[Intent]) -> None:
        if (
            text != instr.text
            and text not in out
            and ("[x]" in text) == has_x
            and classify_intent(text) in want
        ):
            out[text] = tid

    same = frozenset({tau})
    for text, tid in bases:
        if tid:
            keep(text, tid, same)
        for op_id, ops in banks.noise:
            keep(_noisy(text, op_id, ops, seed, route_id, instr.id), f"{tid}+{op_id}" if tid else op_id, same)
    if misleading and tau in banks.misleading:
        for e in banks.misleading[tau][form]:
            keep(fill(e.text, instr.junction), e.id, CONTRADICTS[tau])
    return tuple((text, tid) for text, tid in out.items())
