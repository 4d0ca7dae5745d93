"""The four counterfactual families (the ICR-Drive paper's Algorithm 1), as pure functions.

For each instruction of the baseline sequence, with its baseline intent τ:

- Paraphrase: K entries drawn without replacement from P[τ] (``distance`` entries when the
  baseline text has ``[x]``, else ``plain``), ``{junction}`` filled from the maneuver. Must
  classify as τ.
- Ambiguity: K entries from the global bank A (distance and qualifiers dropped). Must classify
  as unknown.
- Noise: K operations drawn without replacement from N, applied to the baseline text. Must
  classify as τ; a draw whose typo hides the intent is redrawn (up to NOISE_TRIES times).
- Misleading: K entries from M[τ]; must classify as a contradicting intent (left<->right,
  straight/follow -> a turn, lane change to the other side).

Instructions whose τ has no bank (stop, unknown) keep their text. Variant k of a family is the
whole sequence with the k-th draw for every instruction: same ids, triggers and distances.

The control families (does the agent use language at all?):

- Blank: every instruction's text is empty (one variant: K of them would be the same
  sequence); notices are kept.
- Shuffled: K concrete baseline instructions (:func:`~icrsumo.instructions.banks.baseline_catalogue`)
  whose intent is not τ, with ``[x]`` when the baseline text has it, drawn without
  replacement; the route is unchanged, so the text now names another maneuver.

The controls come after the four in the Generator's order, so selecting them leaves the
paper's four families' draws unchanged.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import Instruction, InstructionSet, Intent
from ..vocab import ALL_FAMILIES, FAMILIES, Family, variants_of
from .banks import CONTRADICTS, Banks, Entry, baseline_catalogue, fill
from .intent import classify_intent
from .noise import apply_ops

__all__ = ["ALL_FAMILIES", "FAMILIES", "make_variants"]

NOISE_TRIES = 25


def _draw(rng: np.random.Generator, n: int, k: int, what: str) -> list[int]:
    if k > n:
        raise InputError(what, "", f"bank has {n} entries, cannot draw K={k} without replacement",
                         f"lower --k to {n} or add entries")
    return [int(i) for i in rng.choice(n, size=k, replace=False)]


def _bank_variants(instr: Instruction, family: str, banks: Banks, k: int,
                   rng: np.random.Generator) -> list[tuple[str, str]]:
    """(text, template id) for the K variants of one instruction."""
    tau = instr.intent
    if family == "ambiguity":
        pool: tuple[Entry, ...] = banks.ambiguity
        want: frozenset[Intent] = frozenset({Intent.UNKNOWN})
    else:
        bank = banks.paraphrase if family == "paraphrase" else banks.misleading
        if tau not in bank:
            return [(instr.text, "keep")] * k
        pool = bank[tau]["distance" if "[x]" in instr.text else "plain"]
        want = frozenset({tau}) if family == "paraphrase" else CONTRADICTS[tau]
    out = []
    for i in _draw(rng, len(pool), k, f"{banks.folder}/{family}.json"):
        entry = pool[i]
        text = fill(entry.text, instr.junction)
        got = classify_intent(text)
        if got not in want:
            raise InputError(
                banks.folder / f"{family}.json", f"entry {entry.id}",
                f"{text!r} classifies as {got.value}, not {'/'.join(sorted(w.value for w in want))}",
                "rephrase the entry",
            )
        out.append((text, entry.id))
    return out


def _noise_variants(instr: Instruction, banks: Banks, k: int,
                    rng: np.random.Generator) -> list[tuple[str, str]]:
    tau = instr.intent
    out = []
    for i in _draw(rng, len(banks.noise), k, f"{banks.folder}/noise.json"):
        op_id, ops = banks.noise[i]
        for _ in range(NOISE_TRIES):
            text = apply_ops(instr.text, ops, rng)
            if tau in (Intent.STOP, Intent.UNKNOWN) or classify_intent(text) == tau:
                break
        else:
            raise InputError(banks.folder / "noise.json", f"operation {op_id}",
                             f"{NOISE_TRIES} draws on {instr.text!r} all hid the intent {tau.value}",
                             "use milder primitives")
        out.append((text, op_id))
    return out


def _shuffled_variants(instr: Instruction, banks: Banks, k: int,
                       rng: np.random.Generator) -> list[tuple[str, str]]:
    """(text, template id) for the K ``shuffled`` variants of one instruction."""
    tau = instr.intent
    if tau in (Intent.STOP, Intent.UNKNOWN):
        return [(instr.text, "keep")] * k
    has_x = "[x]" in instr.text
    pool = [(tid, text) for tid, text, intent in baseline_catalogue(banks)
            if intent != tau and ("[x]" in text) == has_x]
    return [(pool[i][1], pool[i][0]) for i in _draw(rng, len(pool), k, f"{banks.folder}/baseline.json")]


def _family_variants(family: str, instr: Instruction, banks: Banks, k: int,
                     rng: np.random.Generator) -> list[tuple[str, str]]:
    if family == Family.NOISE:
        return _noise_variants(instr, banks, k, rng)
    if family == Family.BLANK:
        return [("", "blank")] * k
    if family == Family.SHUFFLED:
        return _shuffled_variants(instr, banks, k, rng)
    return _bank_variants(instr, family, banks, k, rng)


def make_variants(baseline: InstructionSet, families: tuple[str, ...], k: int, banks: Banks,
                  seed: int, rng: np.random.Generator) -> list[InstructionSet]:
    """K variant sequences per family (``blank``: one), in family order then k. ``rng`` drives
    every draw, in a fixed order: family, instruction, k; ``seed`` (the --seed it came from) is
    recorded."""
    sets = []
    for family in families:
        n = variants_of(family, k)
        per_instr = [_family_variants(family, ins, banks, n, rng) for ins in baseline.instructions]
        for kk in range(n):
            instrs = tuple(
                Instruction(
                    id=ins.id, trigger=ins.trigger, text=per_instr[n][kk][0], intent=ins.intent,
                    type=ins.type, distance=ins.distance if "[x]" in per_instr[n][kk][0] else None,
                    maneuver_pos=ins.maneuver_pos, junction=ins.junction,
                    template=per_instr[n][kk][1], source=ins.text,
                )
                for n, ins in enumerate(baseline.instructions)
            )
            sets.append(InstructionSet(route_id=baseline.route_id, family=family, k=kk,
                                       seed=seed, instructions=instrs,
                                       notices=baseline.notices))
    return sets
