"""Rule-based intent classifier for English navigation instructions (standard library only).

``classify_intent(text)`` maps one instruction ("Hang a left after the gas station", "Take the
3rd exit at the roundabout", "Police instruction: change to the right lane now") to an
:class:`~icrsumo.core.types.Intent`. It is deterministic, pure and cached (``functools.lru_cache``);
``normalize(text)`` exposes its token stream.

Step 1 lives in :mod:`icrsumo.instructions.spelling`, steps 2-5 and the precedence in
:mod:`icrsumo.instructions.rules` and the modules it names (mentions as
:class:`~icrsumo.instructions.records.Mention` records), and every word list in
:mod:`icrsumo.instructions.lexicon`.

Pipeline
--------
1. ``normalize``: lower-case; ``[x]`` -> ``<num>``; ordinals ``1st`` -> ``first``; contractions
   (``don't`` -> ``do not``, ``it's`` -> ``it is``); hyphens split words (``right-hand``,
   ``off-ramp``); ``. ! ? ;`` -> ``.`` and ``, : ( ) -- –`` -> ``,`` (clause boundaries);
   runs of 3+ equal letters shrink to 2; spaced-out letters are glued ("l e f t");
   "the round about" -> roundabout. Every other unknown word is spell-corrected to a keyword by
   Damerau-Levenshtein (optimal string alignment) distance within a budget by keyword length:
   0 for <= 2 letters, 1 for 3-5, 2 for >= 6 (capped at 1 when the typed word has <= 4
   letters); words of 1-2 letters are never corrected; ties go to a one-key QWERTY slip, then
   to the same first letter ("pight" -> light, "dight" -> right). The keywords are the rule words
   that matter most and, after them, those that (added one at a time) read more of the hand-written
   commands right under the Noise family's typos and change no bank text's class ("ovre" -> over,
   "unitl" -> until). A word that is itself a known
   English word (``lexicon.KNOWN``: a stop-list of ~900 words including every common false friend:
   light/night/eight/bright, lift/loft/lent/let, line/land/plane, step/shop/top/atop,
   edit/exist, burn/torn/tour, hollow/fellow, during/with/chance ...) is never corrected.
   In a direction slot (after turn/go/bear/keep/veer/hang, after "take a", before "lane" or
   "turn") an unknown word 1 edit from left/right, or 2 edits keeping its first letter or its
   letters, is taken as that side ("turn dight", "turn rgith"), and so are the homophones
   rite/write/strait; a real word there stays what it is ("turn tight" is no turn). An unknown
   word one edit from "slow" before "down" is "slow" ("slwo down").
   Glued words split when both halves are known ("turnleft").
2. Clauses: split at boundaries and at ``and, but, then, so, however, actually, otherwise,
   instead, rather, because, since`` (not ``instead of`` / ``rather than``); each clause keeps
   the word that opened it.
3. Mentions per clause, each with a level: STRONG (explicit left/right/straight, lane change,
   stop, roundabout exit by ordinal), MEDIUM (implied: a highway exit or off-ramp -> RIGHT;
   crossing a junction -- "through/across/past/over the (coming) intersection", "cross the
   junction", "go ahead" when the text names a junction, keeping one's course at or through a
   junction ("maintain your direction at the intersection") -> STRAIGHT) or WEAK (FOLLOW:
   follow, continue, proceed, keep going, stay on/in, carry on, press on, maintain, merge onto /
   enter / join / take a road, on-ramps, a motion verb (roll and cruise included) with
   along/down/onto/forward, a road noun or a compass heading, a bare imperative "Go." / "Just
   drive.", keeping one's course ("hold your heading", "maintain your current course"),
   "straight" along a road in a text that names no junction ("continue driving straight on
   this road"), or starting to drive: start/begin/commence/initiate + driving/the drive/the
   trip, "set off", "get moving", "pull away").

   * left/right is a LANE change when bound to ``lane(s)`` ("left lane", "right-hand lane",
     "lanes to the left", "lane change to the right") or governed by a lane verb ("merge
     left", "move over to the right", "stay on the left", "overtake on the left"). A lane
     phrase beats a turn phrase on the same word ("change to the left lane" is LANE_LEFT).
   * left/right is dropped when it is not a direction ("right now/away/here/after ...",
     "drive right through", "all right", "right of way", "you have left", "from the left
     lane"); when it locates a place ("the destination is on your left", "pass the school on
     your right"; but "take the second road on the right" and "the exit on the left" are
     maneuvers); in a descriptive copular clause without a driving verb ("the right lane is
     closed", but "the next turn is right" / "the only way is left" count; "the left one is
     ending" describes); or when the road
     itself bends ("follow the road as it curves left", "follow the road round to the left").
     Elliptical directions count: a clause that is only "Right (up) ahead", "then it's a
     right", "it's the next left", "your turn is the second right" (copula + determiner or
     ordinal + side); a clause about the turn or exit
     itself names its side ("the turn is a mile away on the right"), and so does a clause that
     is only "on the right" after one about the turn ("the turn is a mile away, on the right"),
     and a counted road on a side ("second street on the right is ours"); "fork" is a turn verb
     ("fork right after the bridge"); "(then) right after the church" with no verb in its
     clause is a turn there; "move into it" after a clause naming a lane on one side is
     a change to that lane ("if the left lane is free, move into it").
   * A clause that forbids ("turning right is prohibited", "left turns are not allowed",
     "straight is closed") contributes nothing, and so does a clause about another road user's
     maneuver: one opening with a road user ("the black car", "a motorbike", "the bus in front
     of you") followed, past a place ("ahead", "in the left lane"), by a verb of its own ("is
     turning left", "will turn", "wants to merge"); it asks the ego for nothing. Passing one on a
     side is a lane change ("overtake the tractor on the right", "pass the cyclist on the left",
     "go around it on the left"); "stay behind it" is FOLLOW. Without punctuation the ego's part
     starts at a condition, an imperative or "you / we" + verb after the road user's verb ("the
     truck ahead is turning right wait behind it", "the car in front wants to turn left you turn
     right"). Fillers at a clause's ends ("please", "now", "ok") do not hide any of this.
   * Commands that are no maneuver: driving faster ("speed up", "go faster", "accelerate", "pick
     up the pace", "put your foot down", "floor it", "hurry up") is FOLLOW; being dropped off or
     let out ("drop me off", "drop me at the corner", "let us out") and letting another road user
     by ("let them pass", "let the bus through", "let it go first", "let it in") is STOP
     ("let me off here" too), a STOP that a
     maneuver after "before" still follows ("let the bus pass before you turn left" -> LEFT);
     "step on it", "gun it", "pick it up", "hurry, we're late" are FOLLOW, "a speed bump coming
     up" is no "speed up".
     Polite asides ("if you don't mind", "if it's not too much trouble") are dropped, and so is
     a first clause "Right," (or "Right then,") before a command of its own ("Right, carry on
     down the high street" -> FOLLOW).
     "Stay / keep right at the fork (the Y-junction, the split)" is a turn.
   * Roundabouts (roundabout/rotary/traffic circle anywhere in the text): exit ordinals map
     1st -> RIGHT, 2nd -> STRAIGHT, 3rd and later -> LEFT ("third exit", "3rd exit",
     "exit 2", "take the first one", "exit at the second opportunity", "leave the roundabout
     by the third"); an exit there with no ordinal is UNKNOWN. An exit counted by an ordinal
     word from "second" on in a text that names neither a roundabout nor a highway ("Second
     exit.", "Roll out on the third exit") is read the same way: highway exits go by number
     or by "next".
   * Elsewhere an exit without a stated side ("Take exit 23B", "Take the exit", "Exit the
     highway", "Leave / quit the motorway", "off-ramp", "come / get off at junction 12 / at the
     next junction / at the slip road") is RIGHT: the bundled towns drive on the right and
     highway exits leave to the right. A stated side wins ("take the exit on the left"); an exit
     driven past is none ("stay on the motorway past this exit"). A dual carriageway is a
     highway. At a roundabout an ordinal counts exits by other names too ("the second turning",
     "the first opportunity", "by the first road").
   * Vague destination talk is UNKNOWN ("Head to the destination", "Go that way"): a motion
     verb needs a road, a heading or along/down/onto to be FOLLOW, while continue / follow /
     proceed / keep going are FOLLOW on their own ("Continue to the destination" -> FOLLOW).
     "U-turn", "turn around" and a turn without a side are UNKNOWN.
   * Stop: stop/halt (not "stop sign", "bus stop", "four-way stop"), "come to a (complete)
     stop", pull over/up/in, brake, wait, park, stand still, stay put, hold your position, hold it.
     Keeping one's lane ("hold this lane") is FOLLOW like keeping one's course.
   * A clause with no mention that is a caution notice ("Stop sign ahead", "Watch out for
     pedestrians", "Yield to cyclists", "Give way", "Slow down", "Traffic light ahead") is a
     NOTICE-level STOP: the weakest mention of all (the baseline bank labels notices "stop").
     So are being aware / mindful / alert of something, "heads up", "keep an eye out", and
     slowing down ("decelerate", "drive slower", "reduce your speed", "easy on the gas", "take
     it slow" but not "the slow lane", "ease off", "you're going too fast", "take it easy", "bring
     your speed down"); speed bumps, speed cameras, school zones and a road that narrows ahead
     are hazards.
4. Negation: ``not, no, never, avoid, skip, ignore, forget, cancel, without, disregard, nor,
   instead of, rather than, stop + -ing`` negate the mentions after them in their clause up to
   the end of the first verb phrase (a new driving verb after a negated mention ends the scope:
   "do not turn left turn right"; so do a new imperative after the negated verb, "don't overtake
   here stay in your lane", "instead of the motorway take the left turn", unless it is reported,
   "ignore the sign saying go straight"; the other side right after a negated side, "no not left
   right"; and a new sentence, "don't turn yet it's the next left"). "Don't forget / miss / fail
   to ..." stays positive. Some
   negations mean something themselves: "don't move / go no further / do not proceed until"
   -> STOP; "don't change lanes", "don't merge yet", "skip this exit", "don't turn here / off",
   "do not deviate
   (stray, swerve, depart) from this route", "don't leave the highway" -> FOLLOW. Two different
   directions joined by "or" ("turn left or right") cancel each other. A maneuver negated with
   "until" / "till" after it is deferred, not refused ("don't turn right until the cars have
   passed" -> RIGHT; a negated stop stays negated). A short clause that only points back ("not
   the first right, the second one"; "not this exit, the next one") asks for the maneuver the
   clause before it negated, and so does "take the second" after "don't take the first left".
5. Subordination: mentions after ``before, after, once, when, whenever, until, till, while, as,
   if, unless`` in their clause, and clauses introduced by ``otherwise``, are subordinate. The
   condition ends at an imperative after it, a base-form driving verb not preceded by a subject,
   modal or determiner ("once clear turn left", "after that head left"; not "when you turn
   left", "if you can go"): what follows is the main clause's. "After that" only orders ("and
   straight after that, a right": "straight" there means at once), and a copula inside a
   condition does not make the command a description ("first right once we're over the bridge").

Precedence (``rules.choose``)
-----------------------------
a. Negated and forbidden mentions are dropped.
b. Within one clause only the highest level survives (an explicit side beats an implied exit
   side, a stated direction beats FOLLOW).
c. Main-clause mentions are used if there are any, else subordinate ones
   ("after turning left, go straight" -> STRAIGHT; "change to the left lane before you turn
   left" -> LANE_LEFT; "turn left if you can, otherwise go straight" -> LEFT). A stop or wait
   before a maneuver is its precondition: when a clause's main mentions are all STOP and its
   condition (``before, until, till``) names a maneuver, the maneuver counts as main ("wait for
   a gap before you turn left" -> LEFT).
d. Any non-FOLLOW intent beats FOLLOW ("turn left and follow the road" -> LEFT); among them the
   last directive in the text wins ("don't go straight, turn left instead" -> LEFT, "stop at
   the light, then turn left" -> LEFT, "turn left, no, right!" -> RIGHT, "use the left lane
   to turn left" -> LEFT, "stop for oncoming traffic, once clear turn left" -> LEFT). A clause
   opened by "and" / "then" that only continues ("continue / carry / keep straight (on)", no
   junction named) after a turn or lane change is FOLLOW, not a maneuver ("slight right at the
   fork and continue straight" -> RIGHT).
e. Otherwise any FOLLOW mention -> FOLLOW; otherwise a caution notice -> STOP; nothing ->
   UNKNOWN.
"""

from __future__ import annotations

from functools import lru_cache

from icrsumo.core.types import Intent

from .rules import choose, mentions
from .spelling import tokens

__all__ = ["classify_intent", "normalize"]


def normalize(text: str) -> list[str]:
    """Canonical lower-case tokens of ``text``: spelling fixed, ``[x]`` -> ``<num>``, ordinals
    spelled out, contractions expanded; clause boundaries as ``,`` (weak) and ``.`` (strong)."""
    return list(tokens(text))


@lru_cache(maxsize=65536)
def classify_intent(text: str) -> Intent:
    """Intent of one English navigation instruction (see the module docstring for the rules)."""
    return choose(mentions(tokens(text)))
