"""The texts of the delivery families (:mod:`.delivery`): distance and ordinal phrasings, the
phrases that open a correction, and notices. Each entry is ``(id, text)``; the slots are
``{dir}`` (left / right), ``{ord}`` (first, second, ...), ``{exit}`` (a roundabout exit's
ordinal) and ``[x]`` (a distance in metres, filled when the agent is shown the text). Every
filled text must classify as the maneuver's intent (corrections, distances, ordinals) or as a
caution notice (notices: stop or unknown, never a maneuver); tests/instructions/test_delivery.py
checks them all with :func:`icrsumo.instructions.intent.classify_intent`.
"""

from __future__ import annotations

#: a turn named by its distance along the route
DISTANCE_TURN: tuple[tuple[str, str], ...] = (
    ("dt0", "In [x] metres, turn {dir}."),
    ("dt1", "Turn {dir} in [x] metres."),
    ("dt2", "After [x] metres, turn {dir}."),
    ("dt3", "In [x] metres, make a {dir} turn."),
    ("dt4", "In [x] metres, take the {dir} turn."),
    ("dt5", "[x] metres ahead, turn {dir}."),
    ("dt6", "Prepare to turn {dir} in [x] metres."),
    ("dt7", "In about [x] metres, turn {dir}."),
)
#: going straight across a junction, named by its distance
DISTANCE_STRAIGHT: tuple[tuple[str, str], ...] = (
    ("ds0", "In [x] metres, go straight on."),
    ("ds1", "In [x] metres, continue straight through the junction."),
    ("ds2", "Go straight ahead at the junction in [x] metres."),
    ("ds3", "In [x] metres, keep straight at the intersection."),
    ("ds4", "After [x] metres, carry straight on through the junction."),
    ("ds5", "[x] metres ahead, go straight across."),
    ("ds6", "In about [x] metres, drive straight through the junction."),
    ("ds7", "Continue straight on in [x] metres at the crossing."),
)
#: a roundabout exit, named by the distance to the roundabout
DISTANCE_ROUNDABOUT: tuple[tuple[str, str], ...] = (
    ("dr0", "In [x] metres, take the {exit} exit at the roundabout."),
    ("dr1", "At the roundabout in [x] metres, take the {exit} exit."),
    ("dr2", "In [x] metres, at the roundabout, take the {exit} exit."),
    ("dr3", "After [x] metres, enter the roundabout and take the {exit} exit."),
)
#: a highway exit, named by its distance
DISTANCE_HIGHWAY_EXIT: tuple[tuple[str, str], ...] = (
    ("dh0", "In [x] metres, take the exit."),
    ("dh1", "In [x] metres, take the highway exit."),
    ("dh2", "In [x] metres, leave the highway at the exit."),
)
#: a turn named by its ordinal among the junctions ahead that offer it
ORDINAL_TURN: tuple[tuple[str, str], ...] = (
    ("ot0", "Take the {ord} {dir}."),
    ("ot1", "Take the {ord} turning on the {dir}."),
    ("ot2", "Turn {dir} at the {ord} opportunity."),
    ("ot3", "Take the {ord} road on the {dir}."),
    ("ot4", "Make the {ord} {dir} turn."),
    ("ot5", "Take the {ord} {dir} turn."),
)
#: what opens a correction, before the baseline's text ("" leaves it bare)
CORRECTION_PREFIXES: tuple[tuple[str, str], ...] = (
    ("c0", "No, sorry — "),
    ("c1", "Sorry, my mistake: "),
    ("c2", "Correction: "),
    ("c3", "Scratch that — "),
    ("c4", "Actually, "),
    ("c5", "No, no — "),
    ("c6", "Sorry, I got that wrong — "),
    ("c7", "Let me correct that: "),
    ("c8", "Forget what I said — "),
    ("c9", "Change of plan: "),
    ("c10", "Sorry, I misspoke: "),
    ("c11", ""),
)
#: notice type -> its texts (LangAuto-style caution notices)
NOTICE_TEXTS: dict[str, tuple[tuple[str, str], ...]] = {
    "notice_traffic_light": (
        ("nl0", "Traffic lights ahead."),
        ("nl1", "Signals ahead, be ready to stop."),
        ("nl2", "Watch the traffic light ahead."),
        ("nl3", "There is a traffic signal coming up."),
        ("nl4", "Approaching traffic lights."),
    ),
    "notice_stop_sign": (
        ("ns0", "Stop sign ahead."),
        ("ns1", "Be ready to stop at the sign ahead."),
        ("ns2", "A stop sign is coming up."),
        ("ns3", "Prepare to stop at the junction ahead."),
    ),
    "notice_pedestrians": (
        ("np0", "Pedestrians crossing ahead."),
        ("np1", "Watch for people on the crosswalk."),
        ("np2", "Mind the pedestrian crossing ahead."),
        ("np3", "People may be crossing the road ahead."),
        ("np4", "Caution: pedestrian crossing."),
    ),
    "notice_merging": (
        ("nm0", "Watch for cars joining from the side road."),
        ("nm1", "Cars may cut in ahead, be careful."),
        ("nm2", "Heads up: cars join from a side road ahead."),
        ("nm3", "Vehicles merging ahead, be ready to slow down."),
        ("nm4", "Another road joins ahead; watch for cars."),
        ("nm5", "Traffic joins from a side road ahead, take care."),
    ),
    "notice_caution": (
        ("nc0", "Watch out for cyclists."),
        ("nc1", "Road works ahead, drive carefully."),
        ("nc2", "Careful, a car may pull out."),
        ("nc3", "Children may be playing near the road."),
        ("nc4", "Cyclists may be on the road, take care."),
        ("nc5", "Heads up: a bus is stopping ahead."),
    ),
}
