"""Steps 2-5 of the intent classifier and its precedence: the clauses of a text, the surviving
mentions of each and the choice among them. The parts live beside it: :mod:`.records` (the
:class:`Mention` records), :mod:`.sides` (left / right), :mod:`.heads` (the mention one token
heads), :mod:`.negation`, :mod:`.conditions` and :mod:`.no_maneuver` (clauses that ask for no
maneuver). :mod:`icrsumo.instructions.intent` documents every rule; the word lists live in
:mod:`icrsumo.instructions.lexicon`."""

from __future__ import annotations

from dataclasses import replace

from icrsumo.core.types import Intent

from . import lexicon as lex
from .conditions import continues, mark_subordinate
from .heads import mention_at
from .negation import drop_alternatives, is_negator, negated, negation_scope, refers_back
from .no_maneuver import ego_part, notice, speed_or_drop_off, third_party, yields
from .records import Context, Level, Mention
from .sides import lane_of, side_of_turn

__all__ = ["Context", "Level", "Mention", "choose", "mentions"]


def _clauses(tokens: tuple[str, ...]) -> list[tuple[tuple[str, ...], str]]:
    """(tokens, opener) for each clause, in text order: the opener is the last boundary or joining
    word before it ("and", "then", "otherwise", ","; "" for the first clause)."""
    out: list[tuple[tuple[str, ...], str]] = []
    start, opener = 0, ""
    for i, tok in enumerate(tokens):
        split = tok in lex.SPLIT and not (tok in lex.NEGATOR_HEADS and is_negator(tokens, i))
        if tok in lex.BOUNDARY or split:
            if i > start:
                out.append((tokens[start:i], opener))
            start, opener = i + 1, tok
    if start < len(tokens):
        out.append((tokens[start:], opener))
    return out


def _is_copular(c: tuple[str, ...], words: set[str]) -> bool:
    """A descriptive clause: a copula, no driving verb, no progressive ("the exit is on your left").
    A copula in a condition after the command does not count ("first right once we're over")."""
    k = next((k for k, t in enumerate(c) if t in lex.SUBORDINATE), 0)
    if k:
        c = c[:k]
        words = set(c)
    if not words & lex.COPULA or words & lex.DIRECTIVE or words & lex.MODAL:
        return False
    if c[0] in lex.COPULA or c[0] == "please":
        return False
    return not any(len(t) > 5 and t.endswith("ing") and t not in lex.ING_NOUNS for t in c)


def _bends(c: tuple[str, ...]) -> bool:
    """Whether the road itself bends in this clause ("the road curves left", "follow the road round
    to the left")."""
    if any(t in lex.BEND and any(s in lex.BEND_SUBJECT for s in c[:k]) for k, t in enumerate(c)):
        return True
    follows = set(c) & lex.FOLLOW_VERBS
    return bool(follows) and any(t in lex.ROUND and k and c[k - 1] in lex.ROAD for k, t in enumerate(c))


def _clause_mentions(c: tuple[str, ...], alt: bool, ctx: Context) -> list[Mention]:
    """Surviving (non-negated, highest-level) mentions of one clause; ``alt``: the clause opens
    with "otherwise" (all its mentions are subordinate)."""
    words = set(c)
    if words & lex.ROAD_USERS and third_party(c):  # another road user's maneuver: none of ours
        k = ego_part(c)  # "... is turning right wait behind it": what follows is the ego's
        return _clause_mentions(c[k:], alt, ctx) if k else notice(c, words, alt)
    other = speed_or_drop_off(c, words) if words & lex.NO_MANEUVER else None
    if other is not None:
        return [Mention(other, Level.STRONG if other is Intent.STOP else Level.WEAK, 0, alt)]
    let = yields(c) if "let" in words else None
    if not words & lex.TRIGGERS_OR_NEG:
        return [replace(let, subordinate=alt)] if let else notice(c, words, alt)
    neg, extra = negation_scope(c) if words & lex.NEGATOR_HEADS else ([False] * len(c), [])
    extra += [let] if let else []
    copula = _is_copular(c, words)
    forbidden = words & lex.PROHIBITED or (copula and words & lex.CLOSED)
    if forbidden or ("not" in words and words & lex.PERMITTED):
        return []  # "turning right is prohibited", "left turns are not allowed", "left is closed"
    bend = bool(words & lex.BEND_WORDS) and _bends(c)
    found = list(extra)
    for i, tok in enumerate(c):
        if tok in lex.TRIGGERS and not neg[i]:
            m = mention_at(c, i, ctx, copula, bend)
            if m is not None:
                found.append(m)
    if extra:
        found.sort(key=lambda m: m.at)
    if "or" in words:
        found = drop_alternatives(c, found)
    if not found:
        return notice(c, words, alt)
    top = max(m.level for m in found)
    found = [m for m in found if m.level == top]
    if not words & lex.SUBORDINATE:
        return [replace(m, subordinate=alt) for m in found]
    return mark_subordinate(c, found, alt)


def choose(found: list[Mention]) -> Intent:
    """The intent that mentions (in text order) ask for, by the precedence rules in
    :mod:`icrsumo.instructions.intent`."""
    pool = [m for m in found if not m.subordinate] or found
    specific = [m.intent for m in pool if m.level >= Level.MEDIUM]
    if specific:
        return specific[-1]
    if any(m.level == Level.WEAK for m in pool):
        return Intent.FOLLOW
    return Intent.STOP if pool else Intent.UNKNOWN  # only caution notices left


def _without_asides(tokens: tuple[str, ...]) -> tuple[str, ...]:
    """``tokens`` without polite asides that would read as a negation or a caution ("if you don't
    mind", "if it's not too much trouble")."""
    if "if" not in tokens:
        return tokens
    out = list(tokens)
    for aside in lex.ASIDES:
        n = len(aside)
        k = next((k for k in range(len(out) - n + 1) if tuple(out[k : k + n]) == aside), None)
        if k is not None:
            del out[k : k + n]
    return tuple(out)


def mentions(tokens: tuple[str, ...]) -> list[Mention]:
    """Every surviving mention of a normalized instruction, clause by clause in text order; a clause
    that only refers back ("the second one") takes the maneuver the clause before it negated, and
    "... and continue straight" after a turn is the turn's continuation (FOLLOW); a clause that is
    only a side ("on the right") after one about the turn or exit gives that side's turn, and "move
    into it" after one naming a lane on one side a change to that lane. Polite
    asides ("if you don't mind") are no part of the command, nor is "Right," before a command of
    its own ("Right, carry on")."""
    tokens = _without_asides(tokens)
    ctx = Context.of(set(tokens))
    clauses = _clauses(tokens)
    if len(clauses) > 1 and clauses[0][0] in lex.DISCOURSE_RIGHT and clauses[1][1] == ",":
        rest = _mentions(clauses[1:], ctx)  # "Right, carry on": a discourse marker
        if any(m.level > Level.NOTICE for m in rest):
            return rest
    return _mentions(clauses, ctx)


def _mentions(clauses: list[tuple[tuple[str, ...], str]], ctx: Context) -> list[Mention]:
    """The mentions of ``clauses`` (see :func:`mentions`)."""
    found: list[Mention] = []
    before: tuple[str, ...] = ()
    for clause, opener in clauses:
        own = _clause_mentions(clause, opener == "otherwise", ctx)
        if not own and before and refers_back(clause):
            own = negated(before, ctx)[-1:]
        elif not own and before:
            own = [m for m in (side_of_turn(clause, before) or lane_of(clause, before),) if m is not None]
        elif opener in lex.CONTINUATION_OPENERS and continues(clause, found):
            own = [replace(m, intent=Intent.FOLLOW, level=Level.WEAK) if m.intent is Intent.STRAIGHT else m
                   for m in own]
        found.extend(own)
        before = clause
    return found
