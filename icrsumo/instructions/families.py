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

from icrsumo.core.errors import Field, InputError
from icrsumo.core.types import Instruction, InstructionSet, Intent
from icrsumo.core.vocab import ALL_FAMILIES, FAMILIES, Family, variants_of

from .banks import CONTRADICTS, Banks, Entry, baseline_catalogue, fill
from .intent import classify_intent
from .noise import apply_ops

__all__ = ["ALL_FAMILIES", "FAMILIES", "extend_variants", "make_variants"]

NOISE_TRIES = 25


def _draw(rng: np.random.Generator, n: int, k: int, what: str,
          used: frozenset[int] = frozenset()) -> list[int]:
    """``k`` distinct indices of a pool of ``n``, none of ``used`` (the entries earlier variants
    took, when a folder's K grows); with none used, exactly ``rng.choice(n, k)``."""
    avail = [i for i in range(n) if i not in used]
    if k > len(avail):
        left = f"{len(avail)} unused" if used else str(n)
        raise InputError(what, "", f"bank has {left} entries, cannot draw K={k} without replacement",
                         f"lower {Field('k')} to {len(avail) + len(used) if used else n} or add entries")
    return [avail[int(i)] for i in rng.choice(len(avail), size=k, replace=False)]


def _bank_variants(instr: Instruction, family: str, banks: Banks, k: int,
                   rng: np.random.Generator, used: frozenset[str] = frozenset()) -> list[tuple[str, str]]:
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
    taken = frozenset(i for i, e in enumerate(pool) if e.id in used)
    for i in _draw(rng, len(pool), k, f"{banks.folder}/{family}.json", taken):
        entry = pool[i]
        text = fill(entry.text, instr.junction)
        assert_intent(text, want, banks.folder / f"{family}.json", f"entry {entry.id}")
        out.append((text, entry.id))
    return out


def assert_intent(text: str, want: frozenset[Intent], file: object, place: str,
                  fix: str = "rephrase the entry") -> None:
    """An InputError naming ``file`` and ``place`` unless ``text`` classifies as one of ``want``."""
    got = classify_intent(text)
    if got not in want:
        raise InputError(file, place,
                         f"{text!r} classifies as {got.value}, not {'/'.join(sorted(w.value for w in want))}",
                         fix)


def _noise_variants(instr: Instruction, banks: Banks, k: int,
                    rng: np.random.Generator, used: frozenset[str] = frozenset()) -> list[tuple[str, str]]:
    tau = instr.intent
    out = []
    taken = frozenset(i for i, (op_id, _) in enumerate(banks.noise) if op_id in used)
    for i in _draw(rng, len(banks.noise), k, f"{banks.folder}/noise.json", taken):
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
                       rng: np.random.Generator, used: frozenset[str] = frozenset()) -> list[tuple[str, str]]:
    """(text, template id) for the K ``shuffled`` variants of one instruction."""
    tau = instr.intent
    if tau in (Intent.STOP, Intent.UNKNOWN):
        return [(instr.text, "keep")] * k
    has_x = "[x]" in instr.text
    pool = [(tid, text) for tid, text, intent in baseline_catalogue(banks)
            if intent != tau and ("[x]" in text) == has_x]
    taken = frozenset(i for i, (tid, _) in enumerate(pool) if tid in used)
    return [(pool[i][1], pool[i][0])
            for i in _draw(rng, len(pool), k, f"{banks.folder}/baseline.json", taken)]


def _family_variants(family: str, instr: Instruction, banks: Banks, k: int,
                     rng: np.random.Generator, used: frozenset[str] = frozenset()) -> list[tuple[str, str]]:
    """(text, template id) of ``k`` variants of one instruction, none from the templates in
    ``used``."""
    if family == Family.NOISE:
        return _noise_variants(instr, banks, k, rng, used)
    if family == Family.BLANK:
        return [("", "blank")] * k
    if family == Family.SHUFFLED:
        return _shuffled_variants(instr, banks, k, rng, used)
    return _bank_variants(instr, family, banks, k, rng, used)


def _sets(baseline: InstructionSet, family: str, per_instr: list[list[tuple[str, str]]], k0: int,
          n: int, seed: int) -> list[InstructionSet]:
    """The ``n`` sequences k0 .. k0 + n - 1 of ``family`` from (text, template) per instruction
    and k."""
    sets = []
    for j in range(n):
        instrs = tuple(
            Instruction(
                id=ins.id, trigger=ins.trigger, text=per_instr[i][j][0], intent=ins.intent,
                type=ins.type, distance=ins.distance if "[x]" in per_instr[i][j][0] else None,
                maneuver_pos=ins.maneuver_pos, junction=ins.junction,
                template=per_instr[i][j][1], source=ins.text,
            )
            for i, ins in enumerate(baseline.instructions)
        )
        sets.append(InstructionSet(route_id=baseline.route_id, family=family, k=k0 + j, seed=seed,
                                   instructions=instrs, notices=baseline.notices))
    return sets


def make_variants(baseline: InstructionSet, families: tuple[str, ...], k: int, banks: Banks,
                  seed: int, rng: np.random.Generator) -> list[InstructionSet]:
    """K variant sequences per family (``blank``: one), in family order then k. ``rng`` drives
    every draw, in a fixed order: family, instruction, k; ``seed`` (the --seed it came from) is
    recorded."""
    sets = []
    for family in families:
        n = variants_of(family, k)
        sets += _sets(baseline, family, [_family_variants(family, ins, banks, n, rng)
                                         for ins in baseline.instructions], 0, n, seed)
    return sets


def extend_variants(baseline: InstructionSet, sets: list[InstructionSet], families: tuple[str, ...],
                    k_new: int, banks: Banks, seed: int, rng: np.random.Generator) -> list[InstructionSet]:
    """``sets`` (K variants per family, as :func:`make_variants` made them) grown to ``k_new``
    per family: the K sequences stay as they are; the new ones k = K .. k_new - 1 are drawn with
    ``rng`` from the templates no earlier sequence of the family used at that instruction, in
    family order (a folder whose --k grows; ``blank`` keeps its one sequence). Family order,
    then k."""
    out = []
    for family in families:
        have = sorted((s for s in sets if s.family == family), key=lambda s: s.k)
        n_new = variants_of(family, k_new) - len(have)
        out += have
        if n_new <= 0:
            continue
        per_instr = []
        for idx, ins in enumerate(baseline.instructions):
            used = frozenset(s.instructions[idx].template for s in have)
            per_instr.append(_family_variants(family, ins, banks, n_new, rng, used))
        out += _sets(baseline, family, per_instr, len(have), n_new, seed)
    return out
