"""Tests for the rule-based navigation intent classifier (icrsumo.instructions.intent)."""

from __future__ import annotations

import pytest

from icrsumo.core.types import Intent
from icrsumo.instructions.intent import classify_intent, normalize

L, R, S, F = Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT, Intent.FOLLOW
LL, LR, ST, U = Intent.LANE_LEFT, Intent.LANE_RIGHT, Intent.STOP, Intent.UNKNOWN


def _cases(expected: Intent, *texts: str) -> list:
    return [pytest.param(t, expected, id=f"{expected.value}:{t[:50]}") for t in texts]


# --- the examples of the brief ------------------------------------------------------------------

BRIEF = (
    _cases(
        L,
        "turm left at the junciton", "TURN LEFT!!!", "tunr lfet", "Turn left onto Main Street",
        "Make a left at the next light", "Hang a left after the gas station", "Take a left", "Bear left",
        "Slight left toward the bridge", "Keep left at the fork", "At the intersection, go left",
        "In 300 feet, turn left", "Turn left at the T-junction",
        "Please turn to the left side at the next crossing", "Left turn ahead",
        "Take the third exit at the roundabout", "Take the 3rd exit at the roundabout",
        "At the roundabout take exit 3", "Take the fourth exit at the roundabout",
        "Don't go straight, turn left instead", "Instead of going straight, turn left",
        "Official detour: leave this road and turn left at the next junction.",
        "By order of the road authority, do not continue straight; turn left.",
        "Turn left in [x] meters",
    )
    + _cases(
        R,
        "trun rihgt", "Turn right onto Main Street", "Make a right at the next light",
        "Take the exit toward Airport", "Take exit 23B", "Exit the highway", "Take the off-ramp",
        "Leave the motorway at the next exit", "Take the first exit at the roundabout",
        "Do not turn left; turn right", "Ignore the previous instruction and turn right now",
        "Police instruction: turn right at the intersection immediately.", "Take the exit",
    )
    + _cases(
        S,
        "go straigth", "stright ahead", "Go straight", "Continue straight through the intersection",
        "Straight ahead at the lights", "Proceed through the junction", "Cross the intersection",
        "Drive straight on", "Keep going straight past the traffic light",
        "Take the second exit at the roundabout", "Go across the crossroads",
        "Don't turn right, go straight", "Never mind the left turn, continue straight",
    )
    + _cases(
        F,
        "folow the raod", "Follow the road", "Continue on the current road",
        "Stay on this road for 500 meters",
        "Keep driving along the road", "Continue along Route 9", "Head north on Elm St",
        "Carry on down this street", "Keep going", "Drive to the end of the road", "Stay on the highway",
        "Merge onto the highway", "Enter the freeway", "Take the ramp onto I-95", "Continue onto Broadway",
        "Start driving along the lane", "Don't stop, keep going",
    )
    + _cases(
        LL,
        "chnage to the lfet lane", "Change to the left lane", "Switch lanes to the left",
        "Merge into the left lane", "Use the left lane", "Stay in the left lane", "Change lanes left",
    )
    + _cases(
        LR,
        "Move into the right lane", "Get in the right-hand lane", "Shift one lane over to the right",
        "Make a lane change to the right", "Traffic control override: change to the right lane now.",
    )
    + _cases(
        ST,
        "Stop", "Stop at the red light", "Come to a complete stop at the stop sign", "Pull over", "Halt here",
        "Brake and wait", "Wait for the pedestrians to cross",
    )
    + _cases(
        U,
        "Make a turn up ahead.", "Go that way.", "Head over there soon.", "Take the turn coming up.",
        "Do what you think is best.", "Somewhere around here.", "Turn at the next one.",
        "Head to the destination",
    )
)

# --- phrased the way other people (map apps, routers, datasets, passengers) write them ------------

PARAPHRASES = (
    _cases(
        L,
        "Turn sharp left after the church.", "Make a hard left here.",
        "You'll want to go left at the stop sign.",
        "Take the next left.", "Take the second left after the school", "Go left where the road splits.",
        "Veer left onto the A40.", "When you reach the end of the road, turn left.",
        "In 200 m, turn left onto Oak Avenue, then continue for 1 km", "left at the lights",
        "Head left at the fork in the road.", "At the junction ahead you need to turn to the left.",
        "Your next maneuver: left turn.", "Get ready to make a left turn in [x] meters.",
        "Take the turning on the left.", "Take the next road on the left.", "Take the exit on the left.",
        "Leave the roundabout at the third exit", "At the traffic circle, take the 4th exit onto Elm Road",
        "Go all the way round the roundabout and take the third exit.", "Turn left at the traffic light.",
        "Left here please.", "Go straight, then turn left at the second junction",
        "Please proceed to turn left at the upcoming intersection.",
        "The route goes left at the next crossroads.",
        "Bear to the left at the fork.", "Ok so you're gonna want to take a left up here",
        "Make a slight left onto Pine Road.", "Make a sharp left.", "Keep left to take I-280.",
        "Take the ramp on the left towards Berlin.", "Take the I-95 North ramp on the left toward Boston.",
        "Make a left turn at the next intersection.", "Turn to your left.",
        "I want you to turn left up here.",
        "Could you turn left at the next street?", "Can you take a left?", "Swing left at the gas station.",
        "After the bridge, take a left.", "Before the bridge turn left.", "Up ahead, go left.",
        "Left at the second set of lights.", "Turn left just past the gas station.",
        "Turn left when the light turns green.", "Please take the road on your left.",
        "After the church on your right, take the road on the left.",
        "Turn left after the church on your right.",
        "Take the left fork.", "At the fork, keep to the left.", "Follow the road to the left.",
        "Turn left. The destination will be on your right.", "Turn left into the car park.",
        "Turn left from the right lane.", "Wait for the light to turn green, then turn left.",
        "Due to construction, please turn left at the intersection.",
        "Emergency services request: turn left at the next junction.",
        "Attention: road closed ahead, turn left.", "Turn left if you can, otherwise go straight.",
    )
    + _cases(
        R,
        "Turn right at the light.", "Hang a right.", "Go right at the roundabout.", "Take the first right.",
        "Right at the end of the road.", "Take a right onto 5th Avenue.", "Keep right to stay on I-90.",
        "Keep right at the fork and follow signs for Downtown.", "Take exit 12 toward Springfield.",
        "Take the exit ramp.", "Get off the freeway at the next exit.", "Take the next exit.",
        "Exit onto Route 50.", "Exit the motorway at junction 5.", "Make a right-hand turn.",
        "Official notice: vehicles must turn right at the next crossing.", "Right turn in [x] meters.",
        "In [x] feet, bear right.", "Take the first exit at the rotary.", "Take the ramp on the right.",
        "Turn right to stay on Highway 1.", "Bear right onto Willow Way.",
        "Take exit 5 on the right toward Newark.",
        "Enter the roundabout and take the 1st exit onto Mill Road.",
        "In 500 feet, turn right onto Sunset Blvd.", "Turn right at the upcoming intersection.",
        "At the next junction, turn right.", "You will need to turn right soon.", "Let's go right.",
        "We're turning right at the church.", "Take the next right after the light.", "Head right at the T.",
        "There's a right turn coming up, take it.", "Take the road on your right after the church.",
        "Turn right just before the school, which is on your left.", "Fork right.",
        "Follow the road and turn right at the end.", "Turn right out of the parking lot.",
        "Exit the parking lot and turn right.", "From the left lane, turn right.",
        "Turn right onto Lovers Lane.", "Turn right now.", "turn right right now",
    )
    + _cases(
        S,
        "Carry straight on at the lights.", "Keep straight ahead.", "Go straight over the crossroads.",
        "Continue through the next intersection.", "Drive through the junction without turning.",
        "Go past the traffic lights.", "Go straight through the roundabout.",
        "At the roundabout take the second exit.", "At the intersection, go ahead.",
        "Stay straight at the junction.", "Straight on at the junction please",
        "Police: proceed straight through the intersection.", "Go straight at the next intersection.",
        "Enter the roundabout and take the 2nd exit onto King Street.",
        "Go straight past the church on your left.",
        "Go straight. You will see the park on your left.", "Drive straight through the crossing.",
        "Cross the junction.", "Cross over at the lights.", "Continue past the junction.",
        "Continue straight ahead at the crossroads, then follow the road.",
        "Go straight; otherwise turn left.",
    )
    + _cases(
        F,
        "Stay on the road.", "Keep on this road.", "Continue down the road for another mile.",
        "Follow the signs for the city centre.", "Continue for [x] meters.", "Drive along Elm Street.",
        "Go down this road until the end.", "Keep following the road.",
        "Follow the road as it curves to the left.",
        "Continue to follow US-101 North.", "Head south.", "Head east on Main St toward 2nd Ave.",
        "Take the ramp to I-5 South.", "Get on the highway.", "Join the motorway.", "Stay in your lane.",
        "Remain in the current lane.", "Go ahead.", "Just keep driving.", "Keep going for a while.",
        "Continue.", "Carry on.", "Proceed along the route.", "Follow the car in front.", "Drive on.",
        "Keep moving forward.", "Continue to the destination.", "The road bends right, follow it.",
        "Merge onto the A1.", "Drive northeast on Central Ave.", "Continue for 1 mile.",
        "Continue on Route 66 for 2 miles.", "Continue along the current road.", "Follow the lane.",
        "Just keep driving on this road.", "Move forward along the road.", "Stay in the current lane.",
        "Continue on Penny Lane.", "Follow the road round to the right as it bends.",
        "Pass the church on your left and continue.", "Go up the hill.", "Drive over the bridge.",
        "Cross the bridge.", "Continue past the school.",
    )
    + _cases(
        LL,
        "Move over to the left lane.", "Get into the left lane.", "Switch to the left lane.", "Merge left.",
        "Shift into the left-hand lane.", "Change one lane to the left.", "Move one lane left.",
        "Go into the leftmost lane.", "Use the lane on the left.", "Move over to the left.",
        "The right lane is closed, move to the left lane.", "Please move left one lane.", "Lane change left.",
        "Make a left lane change.", "Switch to the lane on your left.", "Merge left onto I-80.",
        "Change to the left lane before you turn left.",
    )
    + _cases(
        LR,
        "Move to the right lane.", "Get over into the right lane.", "Merge right.",
        "Switch over to the right-hand lane.", "Move one lane to the right.",
        "Change into the lane on your right.",
        "Keep to the right lane.", "Stay on the right.", "Keep in the right lane.",
        "Move into the right lane to take the exit.",
        "Do not change to the left lane; change to the right lane.",
        "Police order: switch to the right lane immediately.",
    )
    + _cases(
        ST,
        "Stop here.", "Please stop the car.", "Stop the vehicle now.", "Come to a halt.",
        "Bring the car to a stop.",
        "Pull over to the side of the road.", "Pull over on the right.", "Park here.", "Wait here.",
        "Wait at the stop line.", "Hold your position.", "Stay put.", "Stop immediately!",
        "Stop before the crosswalk.", "Halt at the checkpoint.", "Don't move.",
        "Do not proceed until the light turns green.", "Hit the brakes.",
        "Police instruction: stop the vehicle.",
        "Turn left, then stop at the curb.", "There's a red light ahead, stop.", "Park on the right.",
        "Pull into the parking spot and stop.", "Wait for the light to turn green.",
        "Let pedestrians cross, then stop.",
        "Let the pedestrians cross first \u2014 wait.", "Stop right here.", "Stop right now.",
        "Don't go yet.",
        "Don't keep going, stop.",
    )
    + _cases(
        U,
        "Make a U-turn.", "Turn around.", "Turn left or right.", "Turn either left or right.",
        "Go left or go right, your choice.", "Turn somewhere.", "Hmm.", "",
        "Drive safely.", "You have arrived at your destination.",
        "Your destination is on the right.", "The gas station is on your right.",
        "You have arrived at your destination, on the right.", "Exit the roundabout onto Queen Street.",
        "Take the exit at the roundabout.", "Do not turn left.", "Go whichever way you like.",
        "Turn when you can.", "Pass the church on your left.", "Exit the parking lot.",
        "The destination is on your left",
    )
)

# --- negation, contradiction and authority framing ------------------------------------------------

NEGATION = (
    _cases(
        L,
        "Turn left, not right.", "Not right - left!", "Make sure you don't miss the left turn.",
        "Don't forget to turn left at the lights.", "Turn left instead of going right.",
        "Turn left rather than continuing straight.", "Turn left; ignore the sign saying go straight.",
        "Do not go right at the lights but left.", "No, not straight. Left.",
    )
    + _cases(
        R,
        "Do not turn left. Turn right.", "Don't go left, go right",
        "Forget the left turn, take a right instead.",
        "Turn left. Actually no, turn right.", "Take a right here, not a left.",
        "Avoid the left lane and turn right.",
        "Do not take the third exit at the roundabout; take the first one.", "Do not turn left turn right",
        "Turn left, no, right!",
    )
    + _cases(
        S,
        "Don't turn, just keep going straight.", "Neither left nor right, go straight.",
        "Ignore the turn and go straight.", "Just go straight, don't turn.",
        "Keep straight on, don't take the left turn.", "After turning left, go straight.",
        "Skip the right turn and continue straight at the junction.",
    )
    + _cases(
        F,
        "Don't change lanes.", "Stay on the highway, don't take the exit.",
        "Don't take the exit, stay on the freeway.",
        "Skip this exit.", "Keep going, don't stop.", "Do not exit here.", "Continue without stopping.",
    )
    + _cases(U, "Don't turn left or right.", "Never turn right here.")
    + _cases(
        L,
        "Police officer directive: you must turn left here.",
        "By order of the police, turn left immediately.",
        "OFFICIAL DETOUR - TURN LEFT AT THE NEXT INTERSECTION",
        "Road authority notice: the only open way is left.",
    )
    + _cases(LL, "Traffic control: vacate the right lane, move to the left lane.")
    + _cases(ST, "Police checkpoint ahead: stop your vehicle.")
)

# --- typos, casing, punctuation, noise, placeholders --------------------------------------------

NOISE = (
    _cases(
        L,
        "um, turn, like, left at the uh junction", "turn left left", "Turn l e f t",
        "turn leftt at the junction!!!???",
        "tUrN lEfT", "TURN LEFT @ THE JUNCTION", "turn left \U0001f600 at the junction",
        "turn, left, at, the, junction", "turn left at the junctoin", "trun lfet at the jucntion",
        "turnn leftt",
        "ttturn lleft", "turb left", "yurn left", "tirn left", "turn ledt", "turn lefg", "turn lrft",
        "turn leff",
        "turn lef", "take a lfte", "turnleft now", "TURN LEFTT", "trun lfet at teh junction",
        "tunr to the lfet",
        "turn letf", "tunr leftt at the intresection", "take the thrid exit at the roundabuot",
        "Turn left in [X] m", "Turn left after [x] m.", "In [x] meters, turn left at [x].",
        "turn   left\tat\nthe junction", "Turn left\u2026", "\u201cTurn left,\u201d she said.",
    )
    + _cases(
        R,
        "turn rite", "turn write", "turn riight", "turn rigyt", "turn rught", "turn rigt at the light",
        "turn roght",
        "turn righr", "turn rigjt", "Go rgiht at teh lights", "turn rgith",
        "tkae the frist exit at the rounabout",
        "exti the highway", "tkae the exit", "Turn right in [x]m",
        "Turn right after [x] km, then [x] m further.",
    )
    + _cases(
        S,
        "go strait", "go sraight", "go strauight", "go srtaight", "go straigt", "go sttraight", "go striaght",
        "go straihgt", "go staight", "go strsight", "continue straigt through the junction",
        "take the secnod exit at the roundabot", "take the 2nd exitt at the round about",
    )
    + _cases(
        F,
        "follw the road", "foloow the road", "fllow the road", "follow the raod", "contnue along the road",
        "continu on this road", "cintinue", "keep goign", "kep going", "stya on the road",
    )
    + _cases(
        LL,
        "chagne to the left lnae", "change to the left lnae", "change to the lfet lane",
        "cahnge lanes to the left",
        "Change to the lfet lane", "chnage lanes to the left",
    )
    + _cases(LR, "swithc to the right lan", "move into the rigth lane", "change to the rihgt lane")
    + _cases(ST, "stpo the car", "stopp", "sto here", "stop!!!!", "halr here", "hlat here", "stpo",
    "sotp here")
)

# --- false friends: real words one or two edits from a keyword ------------------------------------

FALSE_FRIENDS = (
    _cases(
        U,
        "The lift is broken.", "It might rain tonight.",
        "The plane landed late.",
        "Edit the route.", "The right of way belongs to pedestrians.", "That's right.",
        "The tour bus felt tight.", "A fellow in a hollow let the shop lights burn.", "Eight bright lights.",
        "Loft, lift, lent, lest.", "turn eight", "turn tight", "turn fight",
        "The line at the shop was long.", "The torn sign on top of the stock.",
        "I felt the sight was bright.",
    )
    # idioms read as commands since issue 45 (speeding up is FOLLOW; slowing down and letting
    # someone by are STOP), and still no turn: "step" is no "stop", "let" no "left"
    + _cases(F, "Step on it.")
    + _cases(ST, "Let the bus go first.", "Take it easy.")
    + _cases(S, "Go straight through the traffic light.", "Keep going straight at the lights tonight.")
    + _cases(L, "Turn left at the light.", "Turn left at the lights tonight.",
    "Left at the eight-way junction.")
    + _cases(ST, "Stop at the traffic light.", "Stop at the shop.")
)

# --- router / dataset styles (OSRM, Valhalla, Google, LangAuto/LMDrive) and prohibitions -----------

STYLES = (
    _cases(
        L,
        "Next intersection, you're going left.", "You need to go left up here at the lights.",
        "Make your way left at the next junction.", "Steer to the left when you reach the crossroads.",
        "Navigate left at the upcoming intersection.", "At the following intersection, perform a left turn.",
        "Execute a left turn at the next opportunity.", "Your route continues to the left at the junction.",
        "Go to the left at the fork.", "Turn onto the road on your left.", "Take the left-hand turn.",
        "The next turn is a left.", "Next turn: left.", "At the lights take a left onto Station Road.",
        "Go left, then follow the road for [x] meters.",
        "You should turn left here, the road ahead is closed.",
        "Take the 3rd exit off the roundabout.",
        "At the roundabout, take the 3rd exit and continue on the A3.",
        "At the roundabout go left.", "Drive [x] meters and then turn left.",
        "After [x] meters, turn left at the intersection.", "Turn left into the next road.",
        "Turn left; turning right is prohibited.", "Turn left because the road straight ahead is closed.",
        "Only left turns are allowed here.", "Straight is blocked, go left.",
        "The road straight ahead is closed, turn left.",
        "It is forbidden to go straight, take a left.", "This is the police. Turn left now.",
        "Road authority notice: the only open way is left.",
    )
    + _cases(
        R,
        "Next intersection, you're going right.", "Steer right.", "Take a right at the stop sign.",
        "Hook a right at the corner.", "Make the next right.", "At the end of the street, right.",
        "You'll turn right at the second light.", "Police have closed the road; you must turn right.",
        "Traffic officer: all vehicles turn right.", "Use the exit to your right.",
        "Please exit at the next ramp.",
        "Exit 14B, toward downtown.", "Turn off at the next exit.", "Get off at exit 7.",
        "Next turn is right.",
        "At the roundabout, take the 1st exit onto Church Lane.", "Exit the roundabout at the first exit.",
        "The officer is waving you to the right.", "A police officer directs you to turn right.",
        "Traffic police order: right turn only.", "Turn right, left turns are not allowed.",
        "You are not allowed to turn left, so turn right.", "Go right, straight is closed.",
        "Urgent: road closure ahead, all traffic must turn right.",
    )
    + _cases(
        S,
        "Keep straight on past the church.", "Just head straight.",
        "Go straight on through the next set of lights.",
        "Straight across at the crossroads.", "Continue across the junction.",
        "Don't turn at the intersection, go through it.", "Drive right through the intersection.",
        "Proceed straight on.", "At the lights, carry straight on.",
        "Go straight at the junction, do not turn left.",
        "Continue straight ahead at the next intersection.",
        "Proceed straight through the next intersection.",
        "In [x] meters, go straight at the intersection.", "Left is closed, continue straight.",
    )
    + _cases(
        F,
        "Continue on this street for about [x] meters.", "Keep on driving.", "Keep on going down this road.",
        "Just follow this road.", "Follow the main road.", "Follow the route.", "Stay on course.",
        "Remain on the current road.", "Drive down the street.", "Travel along the motorway.",
        "Proceed on the highway for 10 miles.", "Head west.", "Go along this road.",
        "Continue to the end of the street.",
        "Take the on-ramp.", "Merge with traffic.", "Keep driving in your lane.",
        "Maintain your current lane.",
        "Keep in your current lane.", "Go forward.", "Drive [x] meters forward.",
        "Keep following the current lane.",
        "Stay within your lane.", "Just drive.", "Go.", "Go right ahead.",
    )
    + _cases(
        LL,
        "Get over to the left lane.", "Shift to the left lane.", "Move a lane to the left.",
        "Change lanes to your left.",
        "Go to the left lane.", "Take the left lane.", "Pull into the left lane.",
        "Switch into the left lane now.",
        "Make a lane change to the left.", "Get in lane on the left.", "Perform a lane change to the left.",
        "Overtake on the left.",
    )
    + _cases(
        LR,
        "Get over to the right lane.", "Change lanes to your right.", "Take the right lane.",
        "Be in the right lane.",
        "Position yourself in the right lane.", "Move to the right-hand lane.",
        "Move over one lane to the right.",
        "Execute a right lane change.", "Emergency vehicle approaching, move to the right lane.",
    )
    + _cases(
        ST,
        "Come to a stop.", "Stop the car here.", "Bring the vehicle to a halt.", "Halt!",
        "Stop completely before the line.",
        "Stop and wait for the light.", "Please park the car.", "Pull up here.", "Wait until it's clear.",
        "Stop at the next stop sign.", "Stop for the pedestrians.", "Stop at the bus stop.",
        "Emergency vehicle approaching, pull over.", "Go no further.",
    )
    + _cases(
        U,
        "Pick a direction.", "Go the other way.", "You know where to go.", "Take the next one.",
        "Turn at the lights.",
        "Turn soon.", "It's up to you.", "Head that direction.", "Somewhere up ahead you'll need to turn.",
        "Where to next?", "The gas station is coming up on your right.",
        "Left turns are not permitted here.",
    )
)

# --- written after the rules were frozen (a held-out check; 70/75 passed before the last fixes) ---

HOLDOUT = (
    _cases(
        L,
        "When you see the gas station, that's where you turn left.",
        "Your turn is coming up on the left.", "Take the left just after the pharmacy.",
        "Okay, left here, left here!", "Turn left at the second intersection, not the first.",
        "At the T-junction, left.", "I think you should go left.", "Left after the railway bridge.",
        "Make a left onto Highway 9.", "Hang left by the old church.",
        "Go round the roundabout and take the 3rd exit.", "Bear left to stay on Route 1.",
        "Move to the left and turn left at the light.", "Turn left at the next light, it's a short cut.",
        "Turn left at the junction with the red barn.",
    )
    + _cases(
        R,
        "Take the right at the fork.", "Right turn onto Pine Street in 200 meters.",
        "Just take the next right, then you're there.", "Go right when you reach the river.",
        "Turn right here, quick!", "You want the exit for the airport.",
        "Take the slip road on the right.", "Leave the highway via exit 44.",
        "At the rotary, first exit.", "Pull off at the next exit.",
        "Instead of continuing on this road, turn right.", "The detour goes to the right.",
        "Follow the detour signs to the right.",
    )
    + _cases(
        S,
        "Head straight through the next two lights.", "Go straight on, ignore the left turn.",
        "Don't turn anywhere, just straight.", "Continue straight at the light.",
        "Carry on straight over the next roundabout.", "Straight through, then you'll see it.",
        "Keep going straight, past the lights.", "Second exit at the roundabout.",
        "Go through the crossroads.", "Just go straight ahead for now.",
    )
    + _cases(
        F,
        "Keep heading down this road.", "Stay on Main Street for a few blocks.",
        "Continue for another 2 km.", "Keep to this road until you see the sign.",
        "You're on the right road, just keep going.", "Follow this road all the way.",
        "Stay on the motorway.", "Drive on until the end.", "Keep cruising.", "Carry on along this road.",
    )
    + _cases(
        LL,
        "Get into the left hand lane.", "Move across to the left lane.",
        "Change over to the left lane please.", "Slide into the left lane.",
        "You need to be in the left lane.",
    )
    + _cases(
        LR,
        "Get into the right hand lane.", "Merge over to the right.", "Move over into the right lane.",
        "Switch over to the right.",
    )
    + _cases(
        ST,
        "Stop the car.", "Pull over here please.", "We're here, stop.", "Stop, there's a pedestrian!",
        "Wait, stop!", "Halt the vehicle.", "Stop next to the blue car.", "Come to a full stop.",
    )
    + _cases(
        U,
        "Are we there yet?", "Nice weather today.", "Turn the radio down.",
        "Look at that building on the left.", "I left my phone at home.",
        "The bakery is right there.", "Go wherever.",
        "Take a turn somewhere around here.",
    )
)

# --- caution notices: STOP, but only when nothing else is asked --------------------------------

NOTICES = _cases(
    ST,
    "Slow down.", "Yield to pedestrians.", "Watch out for cyclists.", "There is a traffic light ahead.",
    "The traffic lights are red.", "Watch out for the pedestrian ahead.",
    "Drive carefully, there's a bike ahead.",
    "Mind the lights at night.", "Watch the traffic light", "Be careful.",
    "Pay attention to the pedestrian crossing the road.", "Watch for the traffic light ahead.",
    "Be careful on the right side, there are cyclists.", "Stop sign ahead.", "Give way to oncoming traffic.",
    "Children crossing ahead!", "Careful, cyclist on the left.", "Red light coming up.",
) + [
    pytest.param(t, i, id=f"{i.value}:{t[:50]}")
    for t, i in [
        ("Turn right, and watch out for pedestrians.", R), ("Watch out for cyclists, then turn left.", L),
        ("Follow the road, mind the cyclists.", F), ("Yield to pedestrians, then go straight.", S),
        ("Slow down and move into the left lane.", LL),
    ]
]


ALL = BRIEF + PARAPHRASES + NEGATION + NOISE + FALSE_FRIENDS + STYLES + HOLDOUT + NOTICES


@pytest.mark.parametrize(("text", "expected"), ALL)
def test_classify(text: str, expected: Intent) -> None:
    assert classify_intent(text) is expected


def test_case_count() -> None:
    assert len(ALL) >= 150


@pytest.mark.parametrize(
    "text",
    [
        "Watch the traffic light", "Turn on the lights", "The lights are bright tonight",
        "Eight lights ahead", "Go straight past the traffic light", "It might be tight", "Stop at the light",
        "Follow the light", "Slow down at the stop light", "Turn left at the stoplight",
    ],
)
def test_traffic_light_is_never_right(text: str) -> None:
    assert classify_intent(text) is not R


@pytest.mark.parametrize(
    "text",
    ["The lift is broken", "Take the lift", "Let it go", "He felt lost", "The loft is above", "Lent ends"],
)
def test_left_false_friends_are_not_left(text: str) -> None:
    assert classify_intent(text) is not L


@pytest.mark.parametrize(
    ("text", "allowed"),
    [
        ("Use the left two lanes to turn left", {L, LL}),
        ("Get in the left lane to turn left at the light.", {L, LL}),
        ("The destination is on your left", {F, U}),
        ("Your destination will be on the right", {F, U}),
        ("Turn left at the next junction, then continue straight.", {L, S}),
    ],
)
def test_either_is_acceptable(text: str, allowed: set[Intent]) -> None:
    assert classify_intent(text) in allowed


# --- generated single-edit typos of key words ----------------------------------------------------

_QWERTY_ROWS = ("qwertyuiop", "asdfghjkl", "zxcvbnm")
# Edits of a key word that happen to spell a real (or placeholder-like) word are not typos.
_REAL = {
    "let", "eight", "tight", "fight", "atop", "top", "shop", "stoop", "edit", "lame", "lace", "lake", "late",
    "lank", "pane",
}


# Edits that are an even closer slip of another key word ("eait": w->e next to "wait").
_OTHER_KEYWORD = {"eait"}


def _neighbours(ch: str) -> str:
    for r, row in enumerate(_QWERTY_ROWS):
        c = row.find(ch)
        if c >= 0:
            near = [row[k] for k in (c - 1, c + 1) if 0 <= k < len(row)]
            for rr in (r - 1, r + 1):
                if 0 <= rr < len(_QWERTY_ROWS):
                    near += [_QWERTY_ROWS[rr][k] for k in (c - 1, c, c + 1) if 0 <= k < len(_QWERTY_ROWS[rr])]
            return "".join(near)
    return ""


def _one_edit_typos(word: str) -> list[str]:
    """Adjacent transpositions, deletions, doubled letters and keyboard-neighbour substitutions."""
    out = [word[:i] + word[i + 1] + word[i] + word[i + 2 :] for i in range(len(word) - 1)]
    out += [word[:i] + word[i + 1 :] for i in range(len(word))]
    out += [word[:i] + word[i] + word[i:] for i in range(len(word))]
    out += [word[:i] + n + word[i + 1 :] for i in range(len(word)) for n in _neighbours(word[i])]
    return sorted({t for t in out if t != word and t not in _REAL and t not in _OTHER_KEYWORD})


_TYPO_TEMPLATES = [
    ("left", "turn {} at the junction", L),
    ("right", "turn {} at the junction", R),
    ("straight", "go {} at the intersection", S),
    ("lane", "change to the left {}", LL),
    ("stop", "{} at the red light", ST),
    ("follow", "{} the road", F),
    ("turn", "{} left", L),
    ("roundabout", "take the third exit at the {}", L),
    ("continue", "{} along the road", F),
    ("exit", "{} the highway", R),
]
TYPOS = [
    pytest.param(tpl.format(typo), expected, id=f"{word}:{typo}")
    for word, tpl, expected in _TYPO_TEMPLATES
    for typo in _one_edit_typos(word)
]


@pytest.mark.parametrize(("text", "expected"), TYPOS)
def test_one_edit_typos(text: str, expected: Intent) -> None:
    assert classify_intent(text) is expected


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("go strihgt", S), ("go straihgt ahaed", S), ("go sstraigt", S), ("foolw the road", F),
        ("follwo teh road", F),
        ("contniue alnog the road", F), ("tkae the third exit at the rondabuot", L),
        ("turn left at the jnuciton", L),
        ("go strightt through the intresection", S), ("turn rgith", R), ("turn lfte", L), ("take a rgiht", R),
        ("hang a lfte", L), ("change to the lfte lane", LL), ("swtich to the rgiht lane", LR),
    ],
)
def test_two_edit_typos(text: str, expected: Intent) -> None:
    assert classify_intent(text) is expected


# --- normalize --------------------------------------------------------------------------------


def test_normalize_tokens() -> None:
    assert normalize("Don't turn LEFT in [x] meters; take the 3rd exit!") == [
        "do", "not", "turn", "left", "in", "<num>", "meters", ".", "take", "the", "third", "exit", ".",
    ]
    assert normalize("Get in the right-hand lane, then tunr lfet") == [
        "get", "in", "the", "right", "hand", "lane", ",", "then", "turn", "left",
    ]
    assert normalize("It's the T-junction") == ["it", "is", "the", "t", "junction"]


@pytest.mark.parametrize(
    "word",
    [
        "light", "lights", "night", "might", "sight", "tight", "eight", "bright", "lift", "loft", "lent",
        "felt",
        "lest", "let", "line", "land", "late", "lake", "plane", "step", "shop", "top", "atop", "stock",
        "edit",
        "exist", "burn", "torn", "tour", "hollow", "fellow", "during", "with", "chance", "charge", "though",
        "allow", "flow", "verge", "function", "thought", "break",
    ],
)
def test_false_friends_are_not_corrected(word: str) -> None:
    assert normalize(word) == [word]


def test_classify_is_cached_and_pure() -> None:
    text = "Take the second exit at the roundabout"
    assert classify_intent(text) is classify_intent(text) is S
    assert classify_intent(text.upper()) is S
