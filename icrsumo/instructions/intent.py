"""Rule-based intent classifier for English navigation instructions (standard library only).

``classify_intent(text)`` maps one instruction ("Hang a left after the gas station", "Take the
3rd exit at the roundabout", "Police instruction: change to the right lane now") to an
:class:`~icrsumo.types.Intent`. It is deterministic, pure and cached (``functools.lru_cache``);
``normalize(text)`` exposes its token stream.

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
   to the same first letter ("pight" -> light, "dight" -> right). A word that is itself a known
   English word (``_KNOWN``: a stop-list of ~900 words including every common false friend:
   light/night/eight/bright, lift/loft/lent/let, line/land/plane, step/shop/top/atop,
   edit/exist, burn/torn/tour, hollow/fellow, during/with/chance ...) is never corrected.
   In a direction slot (after turn/go/bear/keep/veer/hang, after "take a", before "lane" or
   "turn") an unknown word 1 edit from left/right, or 2 edits keeping its first letter or its
   letters, is taken as that side ("turn dight", "turn rgith"), and so are the homophones
   rite/write/strait; a real word there stays what it is ("turn tight" is no turn).
   Glued words split when both halves are known ("turnleft").
2. Clauses: split at boundaries and at ``and, but, then, so, however, actually, otherwise,
   instead, rather, because, since`` (not ``instead of`` / ``rather than``).
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
     closed", but "the next turn is right" / "the only way is left" count); or when the road
     itself bends ("follow the road as it curves left"). Elliptical directions count: a clause
     that is only "Right (up) ahead", and "then it's a right" (copula + "a" + side).
   * A clause that forbids ("turning right is prohibited", "left turns are not allowed",
     "straight is closed") contributes nothing, and so does a clause about another road user's
     maneuver: one opening with a road user ("the black car", "a motorbike", "the bus in front
     of you") followed, past a place ("ahead", "in the left lane"), by a verb of its own ("is
     turning left", "will turn", "wants to merge"); it asks the ego for nothing.
   * Commands that are no maneuver: driving faster ("speed up", "go faster", "accelerate", "pick
     up the pace") is FOLLOW; being dropped off or let out ("drop me off", "let us out") is STOP.
     "Stay / keep right at the fork (the Y-junction, the split)" is a turn.
   * Roundabouts (roundabout/rotary/traffic circle anywhere in the text): exit ordinals map
     1st -> RIGHT, 2nd -> STRAIGHT, 3rd and later -> LEFT ("third exit", "3rd exit",
     "exit 2", "take the first one", "exit at the second opportunity", "leave the roundabout
     by the third"); an exit there with no ordinal is UNKNOWN. An exit counted by an ordinal
     word from "second" on in a text that names neither a roundabout nor a highway ("Second
     exit.", "Roll out on the third exit") is read the same way: highway exits go by number
     or by "next".
   * Elsewhere an exit without a stated side ("Take exit 23B", "Take the exit", "Exit the
     highway", "Leave / quit the motorway", "off-ramp") is RIGHT: the bundled towns drive on the right
     and highway exits leave to the right. A stated side wins ("take the exit on the left").
   * Vague destination talk is UNKNOWN ("Head to the destination", "Go that way"): a motion
     verb needs a road, a heading or along/down/onto to be FOLLOW, while continue / follow /
     proceed / keep going are FOLLOW on their own ("Continue to the destination" -> FOLLOW).
     "U-turn", "turn around" and a turn without a side are UNKNOWN.
   * Stop: stop/halt (not "stop sign", "bus stop"), "come to a (complete) stop", pull over/up,
     brake, wait, park, stand still, stay put, hold your position.
   * A clause with no mention that is a caution notice ("Stop sign ahead", "Watch out for
     pedestrians", "Yield to cyclists", "Give way", "Slow down", "Traffic light ahead") is a
     NOTICE-level STOP: the weakest mention of all (the baseline bank labels notices "stop").
     So are being aware / mindful / alert of something, "heads up", and slowing down
     ("decelerate", "reduce your speed", "easy on the gas").
4. Negation: ``not, no, never, avoid, skip, ignore, forget, cancel, without, disregard, nor,
   instead of, rather than, stop + -ing`` negate the mentions after them in their clause up to
   the end of the first verb phrase (a new driving verb after a negated mention ends the scope:
   "do not turn left turn right"). "Don't forget / miss / fail to ..." stays positive. Some
   negations mean something themselves: "don't move / go no further / do not proceed until"
   -> STOP; "don't change lanes", "skip this exit", "don't turn here / off", "do not deviate
   (stray, swerve, depart) from this route", "don't leave the highway" -> FOLLOW. Two different
   directions joined by "or" ("turn left or right") cancel each other.
5. Subordination: mentions after ``before, after, once, when, whenever, until, till, while, as,
   if, unless`` in their clause, and clauses introduced by ``otherwise``, are subordinate.

Precedence (``_choose``)
------------------------
a. Negated and forbidden mentions are dropped.
b. Within one clause only the highest level survives (an explicit side beats an implied exit
   side, a stated direction beats FOLLOW).
c. Main-clause mentions are used if there are any, else subordinate ones
   ("after turning left, go straight" -> STRAIGHT; "change to the left lane before you turn
   left" -> LANE_LEFT; "turn left if you can, otherwise go straight" -> LEFT).
d. Any non-FOLLOW intent beats FOLLOW ("turn left and follow the road" -> LEFT); among them the
   last directive in the text wins ("don't go straight, turn left instead" -> LEFT, "stop at
   the light, then turn left" -> LEFT, "turn left, no, right!" -> RIGHT, "use the left lane
   to turn left" -> LEFT).
e. Otherwise any FOLLOW mention -> FOLLOW; otherwise a caution notice -> STOP; nothing ->
   UNKNOWN.
"""

from __future__ import annotations

import re
from functools import lru_cache

from icrsumo.types import Intent

__all__ = ["classify_intent", "normalize"]

_STRONG, _MEDIUM, _WEAK, _NOTICE = 3, 2, 1, 0


def _words(text: str) -> frozenset[str]:
    return frozenset(text.split())


# --- vocabulary ---------------------------------------------------------------------------------

_LEFT_RIGHT = frozenset({"left", "right"})
_LANE = _words("lane lanes")
_DETS = _words("the a an your this that my our its current same next")
_ORDINALS = {"first": 1, "second": 2, "third": 3, "fourth": 4, "fifth": 5, "sixth": 6, "seventh": 7}
_NUMBER_WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7}
_ROUNDABOUT = _words("roundabout roundabouts rotary circle")
_HIGHWAY = _words(
    "highway highways freeway freeways motorway motorways expressway interstate autobahn turnpike "
    "parkway tollway thruway autoroute beltway"
)
_ROAD = _HIGHWAY | _words(
    "road roads street streets st rd avenue ave boulevard blvd route lane path bridge tunnel "
    "carriageway track"
)
_JUNCTION = _words(
    "junction junctions intersection intersections crossroads crossroad crossing crossings light "
    "lights signal signals roundabout corner"
)
_COMPASS = _words(
    "north south east west northeast northwest southeast southwest northbound southbound eastbound "
    "westbound"
)
_FOLLOW_CONTEXT = _ROAD | _COMPASS | _words("along down up onto on forward forwards")
_MOTION = _words(
    "go goes going drive drives driving head heads heading travel traveling travelling move moving "
    "cruise cruising ride roll rolls rolling"
)
_BARE_MOTION_PREV = _words("just please now simply then and so keep")
_ROAD_VERBS = _words("enter entering join joining take cross crosses")
_FOLLOW_VERBS = _words("follow follows continue continues continuing proceed proceeds proceeding")
_KEEP_NEXT = _words(
    "going driving moving rolling cruising heading on along ahead in to following forward traveling "
    "travelling the this your"
)
_STAY_NEXT = _words("on in along with within the this your")
_DIRECTIVE = _words(
    "turn turning turns go going goes take taking make making keep keeping bear veer head heading drive "
    "driving move moving change changing switch merge merging stay staying continue continuing follow "
    "following proceed exit exiting enter entering stop stopping use get pull cross hang steer swing "
    "shift wait park halt brake carry leave join remain travel"
)
_TURN_NOUN_NEXT = _words("turn turns turning exit ramp fork hander")
_DIR_PREV_MOTION = _words("go going goes head heading drive driving then and")
_DIR_PREV = _DIR_PREV_MOTION | _words(
    "turn turning turns bear bearing veer keep hang steer swing take make the a an to slight slightly "
    "sharp sharply hard your far move merge shift switch change lane lanes next first second third "
    "fourth or not never no quick"
)
_RIGHT_ADVERB_NEXT = _words("through across past ahead along away")
_RIGHT_INTENSIFIED = _words(
    "now away here there after before behind next past then when as until ahead beside by around "
    "where outside under over up down along this that back through across"
)
_RIGHT_PLACE_NEXT = _words("at on in into onto")
_STATIC_PREV = _words("stop halt wait park parked is are was be it located sits lies just pull stay left")
_PREPOSITIONS = _words("to into onto in the")
_LEFT_NOT_DIR_PREV = _words(
    "you we they i he she have has had was were been nothing anything something meters metres "
    "miles km kilometers kilometres feet ft yards m mi minutes seconds time just"
)
_LANE_FWD_SKIP = _words("hand most side two one both of the 2 3 three")
_LANE_VERBS = _words(
    "change changing switch switching shift shifting merge merging move moving get swap overtake"
)
_LANE_VERB_SKIP = _words("over across to into the your one a lane lanes back")
_LANE_KEEP = _words("keep stay drive remain stick overtake pass")
_LANE_BACK_BLOCK = _words("turn turning take exit go bear veer hang") | _JUNCTION
_ROADISH_BEFORE_ON = _words(
    "exit exits ramp road roads street streets turn turning turnoff lane lanes one avenue st rd ave "
    "entrance junction first second third fourth next fork driveway lot garage"
)
_PASS = _words("pass passing past passes by")
_COPULA = _words("is are was were be been will lies lie located sits appears")
_LOCATIVE_SKIP = _COPULA | _words("coming up approaching ahead soon just")
_MODAL = _words("need needs should must want wants have has got ought")
_BEND = _words("curves curve bends bend winds sweeps turns veers swings")
_BEND_SUBJECT = _ROAD | _words("it")
_TRAVERSE = _words("through across over past")
_AHEAD_VERBS = _MOTION | _words("continue proceed carry keep")
#: other road users: a clause opening with one of them and a verb of its own asks nothing of the ego
_ROAD_USERS = _words(
    "car cars truck trucks lorry lorries bus buses van vans cyclist cyclists bike bikes bicycle bicycles "
    "biker bikers motorbike motorbikes motorcycle motorcycles scooter scooters taxi taxis cab vehicle "
    "vehicles pedestrian pedestrians tractor tractors driver drivers ambulance tram trams suv jeep sedan "
    "coach someone somebody"
)
_THIRD_DETS = _words("that those these some another every")
#: words of a place after the road user ("ahead", "behind you", "in front of you", "in the left lane")
_PLACE_WORDS = _words("ahead behind in front of you the left right lane on your next to beside there here "
                      "black white red blue grey gray silver green yellow big small")
_THIRD_VERBS = _words(
    "is are was were will would wants want seems seem has have keeps plans intends starts tries about "
    "turns turning changes changing merges merging overtakes overtaking goes going pulls pulling moves moving"
)
#: a fork's place ("stay right at the fork / the Y-junction / where it splits")
_FORK_PLACE = _JUNCTION | _words("fork forks split y")
_FASTER = _words("accelerate accelerating faster quicker")
_PACE = _words("pace speed")
_US = _words("me us")
_NO_MANEUVER = _FASTER | _words("speed drop let pick")
_STOP_HEADS = _words(
    "stop stops stopping halt standstill brake brakes braking wait waiting park pull stand stay hold"
)
_EXIT_HEADS = _words("exit exits ramp leave leaving off quit quits quitting")
_EXIT_CONTEXT = _HIGHWAY | _words("exit exits ramp")
_TRAVERSE_SKIP = _DETS | _words(
    "next upcoming first second 4 four way traffic stop big main t coming approaching following "
    "forthcoming ensuing subsequent imminent nearest"
)
_CROSS_SKIP = _TRAVERSE_SKIP | _words("over at")
_STOP_NOUN_NEXT = _words("sign signs line lines light lights bar signal signals marker street")
_STOP_NOUN_PREV = _words("bus truck rest pit tram taxi next last first non one")
_STOP_COME = _words("come comes coming bring make pull roll")
_STOP_ADJ = _words("a the complete full sudden abrupt quick emergency gentle rolling dead")
_PARK_PREV = _words("please and then now just to can should must safely")
_PARK_NEXT = _words("here there on at by near behind beside in your the")
_PULL_STOP = _words("over up aside")
_NOT_ROAD_EXIT = _words("parking car garage lot building driveway station vehicle tunnel mall park area")
_NEGATORS = _words(
    "not no never avoid avoiding skip skipping ignore ignoring forget cancel without disregard nor"
)
_NEG_FILLER = _words("to do be you of than")
# "no" that negates nothing: "no sweat, ...", "no problem", "no big deal", "no worries"
_NO_IDIOM = _words("sweat problem problems worries worry biggie big doubt rush hurry pressure stress fuss")
_NEG_CANCEL = _words("forget miss fail neglect hesitate ignore skip")
_NEG_MOTION = _words("move go proceed continue drive moving going driving")
_NEG_MOTION_NEXT = _words("yet further forward anymore any until now here beyond") | {""}
_SPLIT = _words("and but then so however actually otherwise instead rather because since")
_PROHIBITED = _words("prohibited forbidden banned illegal disallowed")
_PERMITTED = _words("allowed permitted possible legal")
_CLOSED = _words("closed blocked")
_ING_NOUNS = _words(
    "parking building buildings crossing crossings morning evening nothing something anything "
    "everything turning ceiling during string spring sibling"
)
_CAUTION = _words(
    "watch caution careful carefully beware alert attention mind yield yielding obey cautious aware mindful "
    "wary vigilant attentive"
)
# slowing down is a caution notice too ("decelerate", "reduce your speed", "ease off the gas")
_DECELERATE = _words("decelerate decelerates decelerating deceleration")
_SPEED = _words("speed speeds velocity pace gas throttle accelerator")
_LESS = _words("reduce reduces reducing reduction lower lowering decrease decreasing cut drop ease easy")
_HAZARD = _words(
    "pedestrian pedestrians people cyclist cyclists bike bikes bicycle children kids animal animals deer "
    "crosswalk crossing obstacle obstacles hazard roadworks signal signals"
)
_LIGHTS = _words("light lights")
_APPROACH = _words("ahead approaching coming upcoming red near")
_SUBORDINATE = _words("before after once when whenever until till while as if unless")
# starting to drive ("commence driving", "begin the trip", "set off", "get moving", "pull away")
_START_VERBS = _words("start starts begin begins commence commences commencing initiate initiates")
_START_OBJECTS = _words("driving drive moving going journey trip route rolling motion ride")
_SET_OFF = {"set": _words("off out forth"), "get": _words("moving going rolling started"),
            "pull": _words("away"), "press": _words("on ahead forward onward onwards"),
            "push": _words("on ahead forward onward onwards")}
# keeping one's course ("maintain your course", "hold your heading"): FOLLOW, or STRAIGHT when it
# is kept at / through a junction ("maintain your direction at the intersection")
_COURSE_KEEP = _words(
    "keep keeps keeping maintain maintains maintaining preserve preserves preserving hold holds holding "
    "stay stays staying remain remains remaining continue continues continuing follow follows"
)
_COURSE = _words("course heading direction trajectory bearing line")
_COURSE_SKIP = _DETS | _words("present existing original")
_AT_JUNCTION = _words("at through across past over")
_EXIT_BY = _words("at by on via using")
# what "don't ..." asks for when it keeps the current road ("do not deviate from this route")
_DEVIATE = _words("deviate deviating stray straying swerve diverge diverging depart departing")
_OR_GAP = _words("or either to the go turn")
_BOUNDARY = frozenset({",", "."})
_HEADS = _LEFT_RIGHT | _LANE | _words("straight stop halt exit ramp follow continue proceed brake wait park")
_SLOT_HOMOPHONES = {"rite": "right", "write": "right", "wright": "right", "strait": "straight"}
_SLOT_PREV = _words("turn turning go bear veer keep hang slight sharp hard")

_FUZZY_TARGETS: tuple[str, ...] = (
    "light", "left", "right", "straight", "turn", "turning", "lane", "lanes", "follow", "continue", "stop",
    "exit", "roundabout", "junction", "intersection", "crossroads", "crossing", "change", "switch", "merge",
    "proceed", "ahead", "road", "street", "highway", "freeway", "motorway", "through", "across", "cross",
    "halt", "brake", "wait", "pull", "keep", "stay", "going", "driving", "instead", "ignore", "never",
    "first", "second", "third", "fourth", "traffic", "carry", "ramp", "drive", "following",
    "start", "stick", "maintain", "maintaining", "course", "direction", "deviate", "commence",
)

_ALIASES: dict[str, tuple[str, ...]] = {
    "dont": ("do", "not"), "doesnt": ("does", "not"), "didnt": ("did", "not"), "cant": ("can", "not"),
    "wont": ("will", "not"), "shouldnt": ("should", "not"), "mustnt": ("must", "not"),
    "isnt": ("is", "not"), "arent": ("are", "not"), "wouldnt": ("would", "not"),
    "couldnt": ("could", "not"), "cannot": ("can", "not"), "thru": ("through",),
    "offramp": ("off", "ramp"), "onramp": ("on", "ramp"), "uturn": ("u", "turn"),
    "leftmost": ("left",), "rightmost": ("right",), "lefthand": ("left", "hand"),
    "righthand": ("right", "hand"), "straightahead": ("straight", "ahead"), "stoplight": ("light",),
    "stoplights": ("lights",), "okay": ("ok",), "alright": ("ok",), "towards": ("toward",),
    "metres": ("meters",), "ont": ("on",), "teh": ("the",), "hte": ("the",), "inot": ("into",),
    "itno": ("into",), "kilometres": ("kilometers",),
    "travelling": ("traveling",),
}
_QWERTY_NEIGHBOURS = {
    "q": "wa", "w": "qeas", "e": "wrsd", "r": "etdf", "t": "ryfg", "y": "tugh", "u": "yihj", "i": "uojk",
    "o": "ipkl", "p": "ol", "a": "qwsz", "s": "awedxz", "d": "serfcx", "f": "drtgvc", "g": "ftyhbv",
    "h": "gyujnb", "j": "huikmn", "k": "jiolm", "l": "kop", "z": "asx", "x": "zsdc", "c": "xdfv",
    "v": "cfgb", "b": "vghn", "n": "bhjm", "m": "njk",
}
_CONTRACTION_STEM = {"wo": "will", "ca": "can", "sha": "shall"}
_CONTRACTION_TAIL = {"'re": "are", "'ll": "will", "'ve": "have", "'d": "would", "'m": "am"}
_IS_PRONOUNS = _words("it there that here what where who he she")

# Real words never spell-corrected: function words, driving vocabulary and every common word within
# the edit budget of a keyword (false friends).
_STOP_LIST = _words(
    """
    a about above across after again against ahead all almost along already also always am an and
    another any anything anywhere are around arrive arrived as ask at away back be because been
    before behind being below beside best between beyond big both but by can car cars come comes
    coming could current did do does doing done down during each either else end enough even ever
    every everything far few find for from front get gets getting give go goes going gone good got
    great had has have he her here him his how i if in into is it its just keep kept know last
    later least less let like little long look lot make many may me might more most much must my
    near need new next no nor not now of off often ok on once one only onto or other our out over
    own past people place please point put quite rather really same see she should side since so
    some something soon still such sure than that the their them then there these they thing think
    this those though through thus till to too toward under until up upon us use used very want was
    way we well were what when where which while who whom whose why will with within without would
    yet you your yours
    road roads street streets avenue boulevard route highway freeway motorway lane lanes path drive
    traffic light lights signal signals sign signs junction intersection crossroads crossing corner
    roundabout rotary circle bridge tunnel exit exits ramp off meters meter feet foot yards yard
    miles mile km kilometers kilometer m ft mi minutes seconds destination station gas petrol school
    church park parking building car truck bus bike cyclist cyclists pedestrian pedestrians vehicle
    vehicles police officer order authority official detour override control instruction
    instructions previous immediately now quickly slowly carefully safely gently red green amber
    yellow north south east west here there fork curve bend hill main speed limit slow fast brake
    brakes wait waiting stop stopped stopping halt pull turn turns turned turning follow following
    continue proceed merge change switch move stay remain head heading toward straight left right
    side hand way ahead destination arrive passing pass lot garage driveway entrance airport center
    centre city town downtown mall hospital market bank hotel shop store square bay
    light lights night nights might sight sights tight eight eighth eighty bright fight fright
    flight slight plight height weight wright rights bight alight lighter lightly mighty blight
    lift lifts loft lent felt lest let lets leaf deft heft weft theft cleft lefty leftover leftovers
    line lines land lands late lake lame lace lance lank lean lone plane planes pane panes sane
    cane vane wane mane lain lawn lang lanky laden laid lame lamp
    step steps shop shops top tops atop stock stoop slop stow stomp strop spot stops stopper
    edit edits exist exists emit exile exits
    burn burns torn tour tours turf term terms urn churn tune tuna
    hollow fellow fellows fallow allow allows flow flows folly follower followers yellow pillow
    mellow willow bellow swallow shallow hallow wallow below
    read reads load loads roam rod rods rode raid broad goad toad roar rad
    sweet steer steep steel sheet stream streams stress strict streak treat tree trees greet strew
    strut stet stent screen spree stereo
    strait straits straighten straightens straightened straightly starlight
    burning churning cunning curing curling during earning hurling hurting morning mourning nursing
    running stunning tuning warning tanning turnip turbine trying tubing
    continued continual convince confine
    function functions auction injunction sanction suction conjunction
    interaction interception intervention interjection
    crossroad browsing costing dressing pressing crushing tossing crowing frosting caressing
    chance chances charge charges range ranges orange oranges channel channels chant chase crane
    cage hinge chafe changer charger exchange cringe flange grange hanger chaste canoe
    with watch witch itch pitch ditch stitch twitch sketch smith snatch swatch hitch swish winch
    swath switches
    emerge emerges verge verges merger mere
    precede process priced proceeds
    head heads
    highly freely leeway doorway motorcar
    thorough though thought tough trough rough throng borough
    access actress caress cress crass gross dross recross
    alt hale half hall halls halo hilt malt salt hat hats hart
    bake brace brave braze broke rake break breaks breaking
    await bait gait waft waif wail waist want wants wart watt whit wit writ
    bull full dull gull hull lull mull null pill poll pulp pall
    deep keen keel kelp peep seep weep jeep beep
    say slay stab stag star stars stray sway stays stayed stat
    doing
    marry parry harry tarry curry hurry scurry merry carrying carried carries cary
    camp camps damp lamp lamps rump romp ram rams rasp cramp tramp rap raps vamp
    dive dives drove driver drivers derive dire diver thrive drier dried drives dove
    flowing hollowing bellowing yellowing swallowing wallowing allowing
    braving craving dicing dining divine diving drawing drilling drinking dripping driven drying
    giving living raving riding rising roving striving writing grieving
    stead instep intend inseam unsteady
    ignite gnome snore
    nut net nit note notes knot hot got dot pot rot cot jot tot nod non snot now
    ever fever lever sever
    fist
    beyond record records send scold scone secant secondly
    thirl
    court couth firth fort forte forth forty fought fount four mouth north worth youth
    roustabout tragic arose drake chancel clang chaise mange whinge backstop crossbar crossover
    downright forthright outright upright straightforward straightway headlight headlights headline
    headlines headlong headway headfirst makeshift getaway goat nonstop stopover useless turnover
    scotch sleet steed gore acres actors aprons arrows acorns carols macros crops crows crocs
    fours forts courts lakes laces lances canes vanes wanes newer proved probed priced pricked
    processed preceded proofed prowled rocked troughs throngs burying curving cursing curbing ruining
    returning spurning surfing surging sunning tiring toning touring terming luring lurking purring
    learning yearning arriving arising deriving depriving drifting draining draping droning pricing
    proving bribing prizing griping grinding frying deicing delving thriving shaving closing choosing
    crashing crowding crowning croaking classing glossing bossing arousing cruising goings list lists
    last lost lint life lead riot rift loot sect sections seconded
    bitch thane chine chape pruning purging gunning thrush strewn screed charged chanted chants crisping
    crusting
    """
)

_RULE_WORDS = (
    _LEFT_RIGHT | _LANE | _DETS | _ROUNDABOUT | _ROAD | _JUNCTION | _COMPASS | _FOLLOW_CONTEXT
    | _MOTION | _FOLLOW_VERBS | _KEEP_NEXT | _STAY_NEXT | _DIRECTIVE | _TURN_NOUN_NEXT | _DIR_PREV
    | _RIGHT_INTENSIFIED | _RIGHT_PLACE_NEXT | _STATIC_PREV | _LEFT_NOT_DIR_PREV | _LANE_FWD_SKIP
    | _LANE_VERBS | _LANE_VERB_SKIP
    | _LANE_KEEP | _ROADISH_BEFORE_ON | _PASS | _COPULA | _BEND | _TRAVERSE | _TRAVERSE_SKIP
    | _STOP_NOUN_NEXT | _STOP_NOUN_PREV | _STOP_COME | _STOP_ADJ | _PARK_PREV | _PARK_NEXT
    | _PULL_STOP | _NOT_ROAD_EXIT | _NEGATORS | _NEG_CANCEL | _NEG_MOTION | _NEG_MOTION_NEXT
    | _SPLIT | _SUBORDINATE | _HEADS | frozenset(_ORDINALS) | frozenset(_NUMBER_WORDS)
    | _words("instead rather of than standstill still put hold position u around back stand sure")
    | _CAUTION | _DECELERATE | _SPEED | _LESS | _START_VERBS | _START_OBJECTS | frozenset(_SET_OFF)
    | frozenset().union(*_SET_OFF.values()) | _COURSE_KEEP | _COURSE | _COURSE_SKIP | _DEVIATE
    | _words("heads quit quits quitting leave leaves") | _NO_IDIOM
)
_KNOWN = _STOP_LIST | _RULE_WORDS | frozenset(_FUZZY_TARGETS)
_NO_SLOT_FIX = _KNOWN - frozenset(_SLOT_HOMOPHONES)
_NEGATOR_HEADS = _NEGATORS | _words("instead rather stop")
# Tokens that can head a mention (see _mention and _follow); any other token is skipped.
_TRIGGERS = (
    _LEFT_RIGHT | _TRAVERSE | _MOTION | _FOLLOW_VERBS | _ROAD_VERBS | frozenset(_ORDINALS)
    | _words(
        "straight stop stops stopping halt standstill brake brakes braking wait waiting park pull stand "
        "stay stays hold exit exits ramp leave leaving off ahead cross crosses merge merging resume carry "
        "keep keeps remain remains maintain stick start begin get quit quits quitting"
    )
    | _START_VERBS | frozenset(_SET_OFF) | _COURSE_KEEP
)
_TRIGGERS_OR_NEG = _TRIGGERS | _NEGATOR_HEADS

_PLACEHOLDER_RE = re.compile(r"\[\s*x\s*\]")
# Spaced-out letters ("l e f t") first, then words, numbers, the placeholder and punctuation.
_TOKEN_RE = re.compile(
    r"[a-z](?: [a-z]){2,}\b|[a-z]+(?:'[a-z]+)*|\d+(?:[.,]\d+)*[a-z]*|<num>|[.!?;]+|[,:()\u2013\u2014]"
    r"|(?<=\s)-+(?=\s)|--"
)
_ORDINAL_RE = re.compile(r"(\d+)(?:st|nd|rd|th)")
_ORDINAL_NAMES = {v: k for k, v in _ORDINALS.items()}
_REPEAT_RE = re.compile(r"([a-z])\1{2,}")


_Found = tuple[int, Intent, int]  # (token index in clause, intent, level)
_Mention = tuple[Intent, int, bool]  # (intent, level, subordinate), in text order


# --- spelling -----------------------------------------------------------------------------------


def _budget(length: int) -> int:
    """Edit budget for ``length`` letters."""
    return 0 if length <= 2 else 1 if length <= 5 else 2


def _osa(a: str, b: str, limit: int) -> int:
    """Optimal-string-alignment distance of ``a`` and ``b``; ``limit + 1`` once above ``limit``."""
    la, lb = len(a), len(b)
    if abs(la - lb) > limit:
        return limit + 1
    before: list[int] = []
    prev = list(range(lb + 1))
    for i in range(1, la + 1):
        ai = a[i - 1]
        cur = [i] + [0] * lb
        row_min = i
        for j in range(1, lb + 1):
            v = min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (ai != b[j - 1]))
            if i > 1 and j > 1 and ai == b[j - 2] and a[i - 2] == b[j - 1] and before[j - 2] + 1 < v:
                v = before[j - 2] + 1
            cur[j] = v
            row_min = min(row_min, v)
        if row_min > limit:
            return limit + 1
        before, prev = prev, cur
    return min(prev[lb], limit + 1)


def _expand_apostrophe(word: str) -> tuple[str, ...]:
    """``don't`` -> do not, ``it's`` -> it is, ``driver's`` -> driver."""
    if word.endswith("n't"):
        stem = word[:-3]
        return (_CONTRACTION_STEM.get(stem, stem), "not")
    for tail, full in _CONTRACTION_TAIL.items():
        if word.endswith(tail):
            return (word[: -len(tail)], full)
    if word.endswith("'s"):
        stem = word[:-2]
        if stem == "let":
            return ("let", "us")
        return (stem, "is") if stem in _IS_PRONOUNS else (stem,)
    return (word.replace("'", ""),)


def _fuzzy(word: str) -> str | None:
    """The closest keyword within its edit budget, or None ("pight" -> light, "rigjt" -> right)."""
    best, best_key = None, (99, True, True)
    n = len(word)
    for kw in _FUZZY_TARGETS:
        limit = min(_budget(len(kw)), _budget(n + 1))
        if abs(len(kw) - n) > limit:
            continue
        d = _osa(word, kw, limit)
        if d <= limit:
            # ties: a keyboard-neighbour slip, then the same first letter, then list order
            key = (d, not _neighbour_slip(word, kw), kw[0] != word[0])
            if key < best_key:
                best, best_key = kw, key
    return best


def _neighbour_slip(word: str, kw: str) -> bool:
    """Whether ``word`` is ``kw`` with one letter replaced by a QWERTY neighbour ("wxit")."""
    if len(word) != len(kw):
        return False
    diff = [(a, b) for a, b in zip(word, kw) if a != b]
    return len(diff) == 1 and diff[0][0] in _QWERTY_NEIGHBOURS.get(diff[0][1], "")


def _split_glued(word: str) -> tuple[str, str] | None:
    """``turnleft`` -> (turn, left): both halves known and one of them a keyword."""
    for k in range(2, len(word) - 1):
        a, b = word[:k], word[k:]
        if a in _KNOWN and b in _KNOWN and (a in _HEADS or b in _HEADS or a in _DIRECTIVE):
            return a, b
    return None


@lru_cache(maxsize=65536)
def _correct(word: str) -> tuple[str, ...]:
    """Canonical token(s) for one raw word."""
    if "'" in word:
        out: tuple[str, ...] = ()
        for part in _expand_apostrophe(word):
            out += _correct(part) if part else ()
        return out
    if word in _ALIASES:
        return _ALIASES[word]
    if _REPEAT_RE.search(word):
        return _correct(_REPEAT_RE.sub(r"\1\1", word))
    if word in _KNOWN or len(word) < 3 or not word.isalpha():
        return (word,)
    fixed = _fuzzy(word)
    if fixed is not None:
        return (fixed,)
    return _split_glued(word) or (word,)


@lru_cache(maxsize=65536)
def _slot_direction(word: str) -> str | None:
    """left/right for a typo in a direction slot, else None: one edit ("turn dight"), or two
    edits keeping the first letter or the letters ("turn rgith")."""
    for kw in ("left", "right"):
        d = _osa(word, kw, 2)
        if d <= 1 or (d == 2 and (word[0] == kw[0] or sorted(word) == sorted(kw))):
            return kw
    return None


def _direction_slot(out: list[str], i: int) -> bool:
    """Whether token ``i`` sits where a direction is expected ("turn _", "take a _", "_ lane")."""
    prev = out[i - 1] if i else ""
    if prev in _SLOT_PREV or (prev == "a" and i >= 2 and out[i - 2] in ("take", "make", "hang")):
        return True
    return i + 1 < len(out) and out[i + 1] in ("lane", "lanes", "turn")


def _raw_words(text: str) -> list[str]:
    """Regex tokens of ``text``, lower-cased, with ``[x]`` replaced by ``<num>``."""
    text = text.lower().replace("\u2019", "'").replace("\u2018", "'").replace("`", "'")
    if "[" in text:
        text = _PLACEHOLDER_RE.sub(" <num> ", text)
    return _TOKEN_RE.findall(text)


@lru_cache(maxsize=65536)
def _canonical(raw: str) -> tuple[str, ...]:
    """Canonical token(s) of one regex token (boundary, number, ordinal or word)."""
    if raw[0] in ".!?;":
        return (".",)
    if not raw[0].isalnum() and raw != "<num>":
        return (",",)
    if raw[0].isdigit():
        m = _ORDINAL_RE.fullmatch(raw)
        return (_ORDINAL_NAMES.get(int(m.group(1)), "<ord>") if m else raw,)
    return _correct(raw.replace(" ", ""))  # "l e f t" -> left


def _fix_slot(out: list[str], i: int, raw: str) -> str:
    """Token ``i`` (typed as ``raw``) after the second pass: typos and homophones in a direction
    slot ("turn rgith", "turn rite", "turn dight" which alone would read as light)."""
    tok = out[i]
    if tok in _SLOT_HOMOPHONES and _direction_slot(out, i):
        return _SLOT_HOMOPHONES[tok]
    typo = raw if tok != raw and tok not in _LEFT_RIGHT else tok
    if typo not in _KNOWN and len(typo) >= 3 and typo.isalpha() and _direction_slot(out, i):
        return _slot_direction(typo) or tok
    return tok


def _join_round_about(out: list[str]) -> list[str]:
    """Join "the round about" into "the roundabout"."""
    if "about" not in out:
        return out
    joined: list[str] = []
    for tok in out:
        if tok == "about" and len(joined) >= 2 and joined[-1] == "round" and joined[-2] in _DETS:
            joined[-1] = "roundabout"
        else:
            joined.append(tok)
    return joined


def _typed(raw_words: list[str]) -> list[tuple[str, str]]:
    """(canonical token, word as typed) pairs; a word expanded into several tokens types itself."""
    pairs: list[tuple[str, str]] = []
    for raw in raw_words:
        toks = _canonical(raw)
        pairs.extend((tok, raw if len(toks) == 1 else tok) for tok in toks)
    return pairs


def _tokens(text: str) -> tuple[str, ...]:
    pairs = _typed(_raw_words(text))
    out = [tok for tok, _ in pairs]
    fixed = [
        t if t == r and (t in _NO_SLOT_FIX or not t.isalpha()) else _fix_slot(out, i, r)
        for i, (t, r) in enumerate(pairs)
    ]
    return tuple(_join_round_about(fixed))


def normalize(text: str) -> list[str]:
    """Canonical lower-case tokens of ``text``: spelling fixed, ``[x]`` -> ``<num>``, ordinals
    spelled out, contractions expanded; clause boundaries as ``,`` (weak) and ``.`` (strong)."""
    return list(_tokens(text))


# --- clause analysis -----------------------------------------------------------------------------


def _clauses(tokens: tuple[str, ...]) -> list[tuple[tuple[str, ...], bool]]:
    """(tokens, introduced-by-otherwise) for each clause, in text order."""
    out: list[tuple[tuple[str, ...], bool]] = []
    start, alt = 0, False
    for i, tok in enumerate(tokens):
        if tok in _BOUNDARY or (tok in _SPLIT and not (tok in _NEGATOR_HEADS and _is_negator(tokens, i))):
            if i > start:
                out.append((tokens[start:i], alt))
            start, alt = i + 1, tok == "otherwise"
    if start < len(tokens):
        out.append((tokens[start:], alt))
    return out


def _is_negator(c: tuple[str, ...], i: int) -> bool:
    tok = c[i]
    nxt = c[i + 1] if i + 1 < len(c) else ""
    return (
        (tok in _NEGATORS and not (tok == "no" and nxt in _NO_IDIOM))
        or (tok in ("instead", "rather") and nxt in ("of", "than"))
        or (tok == "stop" and nxt.endswith("ing") and nxt != "stopping")
    )


def _negated_meaning(c: tuple[str, ...], j: int) -> Intent | None:
    """What negating the phrase at ``j`` asks for: "don't move" -> STOP, "don't change lanes",
    "skip this exit" or "don't turn here" -> FOLLOW; None otherwise."""
    target = c[j] if j < len(c) else ""
    after = c[j + 1] if j + 1 < len(c) else ""
    if target in ("further", "farther") or (target in _NEG_MOTION and after in _NEG_MOTION_NEXT):
        return Intent.STOP
    lane_keep = target in ("change", "switch") and after in _LANE and not (_LEFT_RIGHT & set(c[j:]))
    bare_turn = target == "turn" and after in ("", "here", "yet", "now", "anywhere", "at", "off")
    if target in _DEVIATE or (target in ("leave", "quit") and _followed_by(c, j, _ROAD, 3)):
        return Intent.FOLLOW  # "do not deviate from this route", "don't leave the highway"
    if lane_keep or bare_turn or "exit" in c[j : j + 4] or "exits" in c[j : j + 4]:
        return Intent.FOLLOW
    return None


def _negation(c: tuple[str, ...]) -> tuple[list[bool], list[tuple[int, Intent]]]:
    """Per-token negation flags and extra mentions implied by negation ("don't move" -> STOP)."""
    n = len(c)
    neg = [False] * n
    extra: list[tuple[int, Intent]] = []
    active = seen = False
    i = 0
    while i < n:
        if c[i] in _NEGATOR_HEADS and _is_negator(c, i):
            j = i + 1
            while j < n and c[j] in _NEG_FILLER:
                j += 1
            if j < n and c[j] in _NEG_CANCEL:  # "don't forget to turn left"
                i, active = j + 1, False
                continue
            meaning = _negated_meaning(c, j)
            if meaning is not None:
                extra.append((j, meaning))
            i, active, seen = i + 1, True, False
            continue
        if active and c[i] in _DIRECTIVE and seen:
            active = False
        elif active:
            neg[i] = True
            seen = seen or c[i] in _HEADS
        i += 1
    return neg, extra


def _is_direction(c: tuple[str, ...], i: int) -> bool:
    """Whether left/right at ``i`` names a direction (not "right now", "you have left")."""
    tok = c[i]
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if tok == "left":
        past = prev in _LEFT_NOT_DIR_PREV and not (i >= 2 and c[i - 2] in _PREPOSITIONS)  # "you have left"
        return not past and nxt not in ("over", "behind", "alone", "unattended")
    if nxt == "of" and i + 2 < len(c) and c[i + 2] == "way":
        return False
    if prev in _DIR_PREV:
        return not (prev in _DIR_PREV_MOTION and nxt in _RIGHT_ADVERB_NEXT)  # "drive right through it"
    if prev == "all" or (prev in ("is", "are") and i >= 2 and c[i - 2] in ("that", "you", "thats")):
        return False
    if i == 0 and "ahead" in c[1:] and set(c[1:]) <= {"up", "ahead", "just"}:
        return True  # the whole clause is "Right (up) ahead."
    if nxt in _RIGHT_PLACE_NEXT:
        if prev in ("stay", "keep") and nxt == "at" and any(t in _FORK_PLACE for t in c[i + 2:i + 5]):
            return True  # "stay right at the fork / the Y-junction"
        return prev not in _STATIC_PREV  # "stop right at the line" vs "hda right at the junction"
    return nxt not in _RIGHT_INTENSIFIED


def _lane_bound(c: tuple[str, ...], i: int) -> bool:
    """Whether left/right at ``i`` qualifies a lane ("left lane", "lanes to the left")."""
    for j in range(i + 1, min(i + 4, len(c))):
        if c[j] in _LANE:
            return True
        if c[j] not in _LANE_FWD_SKIP:
            break
    for j in range(i - 1, max(i - 7, -1), -1):
        if c[j] in _LANE:
            return True
        if c[j] in _LANE_BACK_BLOCK or c[j] in _LEFT_RIGHT:
            return False
    return False


def _lane_verb(c: tuple[str, ...], i: int) -> bool:
    """Whether a lane verb governs left/right at ``i`` ("merge left", "stay on the right")."""
    j = i - 1
    while j >= 0 and c[j] in _LANE_VERB_SKIP:
        j -= 1
    if j >= 0 and c[j] in _LANE_VERBS:
        return True
    return i >= 3 and c[i - 1] in ("the", "your") and c[i - 2] in ("on", "in") and c[i - 3] in _LANE_KEEP


def _locative(c: tuple[str, ...], i: int) -> bool:
    """Whether "on (your|the) left/right" at ``i`` describes a place, not a maneuver."""
    if i < 2 or c[i - 1] not in ("your", "the") or c[i - 2] != "on":
        return i >= 1 and c[i - 1] == "on"
    k = i - 3
    while k >= 0 and c[k] in _LOCATIVE_SKIP:
        k -= 1
    if k < 0 or c[k] not in _ROADISH_BEFORE_ON:
        return True
    head = c[:k]
    return bool(_PASS & set(head)) or any(t in _LEFT_RIGHT for t in head)


def _left_right(c: tuple[str, ...], i: int, copula: bool, bend: bool) -> Intent | None:
    """Intent of left/right at ``i``, or None when it is no maneuver."""
    tok = c[i]
    if not _is_direction(c, i):
        return None
    if (i and c[i - 1] == "from") or (i >= 2 and c[i - 2] == "from" and c[i - 1] in _DETS):
        return None
    lane = Intent.LANE_LEFT if tok == "left" else Intent.LANE_RIGHT
    turn = Intent.LEFT if tok == "left" else Intent.RIGHT
    if ("lane" in c or "lanes" in c) and _lane_bound(c, i):
        return None if copula else lane
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if nxt in _TURN_NOUN_NEXT or (nxt == "hand" and i + 2 < len(c) and c[i + 2] in _TURN_NOUN_NEXT):
        return turn
    if copula and not bend and i and (c[i - 1] in _COPULA or (
            nxt == "" and i >= 2 and c[i - 1] == "a" and c[i - 2] in _COPULA)):
        return turn  # "the only open way is left", "then it's a right"
    if copula or bend:
        return None
    if _lane_verb(c, i):
        return lane
    return None if _locative(c, i) else turn


def _exit_ordinal(c: tuple[str, ...], i: int) -> int | None:
    """Ordinal of the exit word at ``i`` ("third exit", "exit 2", "exit number two")."""
    for j in (i - 1, i - 2):
        if j >= 0 and c[j] in _ORDINALS:
            return _ORDINALS[c[j]]
    j = i + 1
    if j < len(c) and c[j] == "number":
        j += 1
    if j < len(c):
        if c[j] in _NUMBER_WORDS:
            return _NUMBER_WORDS[c[j]]
        if c[j].isdigit() and 0 < int(c[j]) < 10:
            return int(c[j])
    # "exit at the second (one / opportunity)", "exit the roundabout by the third"
    for j in range(i + 2, min(i + 7, len(c))):
        if c[j] in _ORDINALS and c[j - 1] == "the" and (j == i + 2 or c[j - 2] in _EXIT_BY):
            return _ORDINALS[c[j]]
    return None


def _ordinal_intent(k: int) -> Intent:
    return Intent.RIGHT if k == 1 else Intent.STRAIGHT if k == 2 else Intent.LEFT


def _stop_word(c: tuple[str, ...], i: int) -> bool:
    """Whether stop/halt at ``i`` is the verb (or "come to a stop"), not "stop sign"."""
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if nxt in _STOP_NOUN_NEXT or prev in _STOP_NOUN_PREV:
        return False
    if prev in _STOP_ADJ:
        return any(t in _STOP_COME for t in c[:i])
    return True


def _followed_by(c: tuple[str, ...], i: int, words: frozenset[str], span: int = 4) -> bool:
    return any(t in words for t in c[i + 1 : i + 1 + span])


def _mention(
    c: tuple[str, ...], i: int, ctx: tuple[bool, bool, bool], copula: bool, bend: bool
) -> tuple[Intent, int] | None:
    """The mention headed by token ``i`` of clause ``c`` as (intent, level), or None.
    ``ctx``: whether the text names a roundabout, a junction, a highway."""
    roundabout, junction, highway = ctx
    tok = c[i]
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if tok in _LEFT_RIGHT:
        intent = _left_right(c, i, copula, bend)
        return (intent, _STRONG) if intent is not None else None
    if tok == "straight":
        if (nxt == "away" and prev not in _MOTION) or bend or copula:
            return None
        if not junction and _along_road(c, i):  # "drive straight on this road": no junction to cross
            return Intent.FOLLOW, _WEAK
        return Intent.STRAIGHT, _STRONG
    if tok in _STOP_HEADS and _stop_mention(c, i, tok, prev, nxt):
        return Intent.STOP, _STRONG
    if tok in _EXIT_HEADS or tok in _ORDINALS:
        return _exit_mention(c, i, tok, prev, nxt, roundabout, highway)
    if tok in _TRAVERSE or tok in ("cross", "crosses"):
        if _crosses_junction(c, i, junction):
            return Intent.STRAIGHT, _MEDIUM
    elif tok == "ahead":
        if not any(t in _AHEAD_VERBS for t in c[max(0, i - 2) : i]):
            return None
        return (Intent.STRAIGHT, _MEDIUM) if junction else (Intent.FOLLOW, _WEAK)
    if tok in _COURSE_KEEP:
        kept = _course(c, i, junction)
        if kept is not None:
            return kept
    return _follow(c, i, tok, nxt)


def _along_road(c: tuple[str, ...], i: int) -> bool:
    """Whether "straight" at ``i`` runs along a road ("straight on this road", "straight down
    the highway") rather than across a junction."""
    return i + 1 < len(c) and c[i + 1] in ("on", "along", "down", "up") and any(
        t in _ROAD for t in c[i + 2 : i + 5])


def _course(c: tuple[str, ...], i: int, junction: bool) -> tuple[Intent, int] | None:
    """Keeping one's course at ``i`` ("maintain your course", "hold your current heading"):
    STRAIGHT when it is kept at / through a junction, else FOLLOW; None when no course noun
    follows."""
    j = i + 1
    while j < len(c) and j <= i + 3 and c[j] in _COURSE_SKIP:
        j += 1
    if j >= len(c) or c[j] not in _COURSE:
        return None
    k = j + 2 if j + 1 < len(c) and c[j + 1] == "straight" else j + 1
    if k < len(c) and c[k] in _AT_JUNCTION and _crosses_junction(c, k, junction):
        return Intent.STRAIGHT, _MEDIUM
    return Intent.FOLLOW, _WEAK


def _stop_mention(c: tuple[str, ...], i: int, tok: str, prev: str, nxt: str) -> bool:
    """Whether stop/halt/brake/wait/park/pull/stand/stay/hold at ``i`` asks to stop."""
    if tok in ("stop", "stops", "stopping", "halt"):
        return _stop_word(c, i)
    if tok in ("standstill", "brake", "brakes", "braking", "wait", "waiting"):
        return nxt not in ("light", "lights")
    if tok == "park":
        return prev not in _DETS and (not prev or prev in _PARK_PREV or nxt in _PARK_NEXT)
    if tok == "pull":
        return nxt in _PULL_STOP or (nxt == "off" and not _followed_by(c, i, _EXIT_CONTEXT, 5))
    if tok == "hold":
        return nxt in ("still", "here", "position") or c[i + 2 : i + 3] == ("position",)
    return (tok == "stand" and nxt == "still") or (tok == "stay" and nxt in ("put", "still"))


def _exit_mention(
    c: tuple[str, ...], i: int, tok: str, prev: str, nxt: str, roundabout: bool, highway: bool
) -> tuple[Intent, int] | None:
    """Exits, ramps and leaving a highway: roundabout ordinals, else an implied RIGHT. An exit
    counted by an ordinal word in a text that names no highway ("Second exit.") is read as a
    roundabout exit; highway exits go by number ("exit 23B") or by "next"."""
    if tok in ("exit", "exits"):
        j = i + 1
        while j < len(c) and c[j] in _DETS:
            j += 1
        if j < len(c) and c[j] in _NOT_ROAD_EXIT:  # "exit the parking lot"
            return None
        if roundabout:
            k = _exit_ordinal(c, i)
            return (_ordinal_intent(k), _STRONG) if k else None
        k = _ORDINALS.get(prev, 0)
        if k >= 2 and not highway:
            return _ordinal_intent(k), _STRONG
        return Intent.RIGHT, _MEDIUM
    if tok in _ORDINALS:  # "take the first (one)" at a roundabout
        if roundabout and prev == "the" and nxt in ("", "one"):
            return _ordinal_intent(_ORDINALS[tok]), _STRONG
        return None
    if tok == "ramp":
        return (Intent.RIGHT, _MEDIUM) if prev == "off" else (Intent.FOLLOW, _WEAK)
    if _followed_by(c, i, _HIGHWAY, 3):  # leave / get off the motorway
        return Intent.RIGHT, _MEDIUM
    return _follow(c, i, tok, nxt)


def _crosses_junction(c: tuple[str, ...], i: int, junction: bool) -> bool:
    """Whether ``c[i]`` crosses a junction ("through the junction", "cross it", "go through it")."""
    skip = _TRAVERSE_SKIP if c[i] in _TRAVERSE else _CROSS_SKIP
    j = i + 1
    while j < len(c) and c[j] in skip:
        j += 1
    return j < len(c) and (c[j] in _JUNCTION or (c[j] == "it" and junction))


def _follow(c: tuple[str, ...], i: int, tok: str, nxt: str) -> tuple[Intent, int] | None:
    """FOLLOW mentions: follow/continue/keep going/stay on/merge onto/motion along a road, and
    starting to drive (start/begin/commence driving, set off, get moving, pull away, press on)."""
    if tok == "heads" and nxt == "up":  # "heads up": a warning, not a motion
        return None
    follow = (
        tok in _FOLLOW_VERBS
        or tok in ("merge", "merging", "resume")
        or (tok == "carry" and nxt == "on")
        or (tok in ("keep", "keeps") and nxt in _KEEP_NEXT)
        or (tok in ("stay", "stays", "remain", "remains", "maintain") and nxt in _STAY_NEXT)
        or (tok == "stick" and nxt in ("to", "with"))
        or (tok in ("start", "begin") and nxt in ("driving", "moving", "going"))
        or (tok in _START_VERBS and _followed_by(c, i, _START_OBJECTS, 3))
        or (tok in _SET_OFF and nxt in _SET_OFF[tok])
        or (tok in _MOTION and _followed_by(c, i, _FOLLOW_CONTEXT, 8))
        or (tok in _MOTION and i == len(c) - 1 and (i == 0 or c[i - 1] in _BARE_MOTION_PREV))
        or (tok in _ROAD_VERBS and _followed_by(c, i, _ROAD, 3))
        or (tok == "get" and nxt in ("on", "onto") and _followed_by(c, i, _ROAD, 4))
    )
    return (Intent.FOLLOW, _WEAK) if follow else None


def _third_party(c: tuple[str, ...]) -> bool:
    """A clause about another road user ("the black car is turning left", "a motorbike is
    changing into the right lane", "the bus in front of you will turn left"): it opens with a
    noun phrase headed by a road user, then (past a place: "ahead", "behind you", "in the left
    lane") an auxiliary or a verb of its own. Its directions ask the ego for nothing."""
    head = next((k for k in range(min(len(c), 5)) if c[k] in _ROAD_USERS), None)
    if head is None or (head and c[0] not in _DETS | _THIRD_DETS):
        return False
    if any(t in _DIRECTIVE or t in _LANE_VERBS for t in c[1:head]):
        return False
    k = head + 1
    while k < len(c) and c[k] in _PLACE_WORDS:
        k += 1
    return k < len(c) and c[k] in _THIRD_VERBS


def _speed_or_drop_off(c: tuple[str, ...], words: set[str]) -> Intent | None:
    """Commands that are no maneuver: driving faster ("speed up", "go faster", "accelerate",
    "pick up the pace") keeps to the road (FOLLOW); being dropped off / let out is a STOP."""
    if words & _FASTER or ("speed" in words and "up" in words) or ({"pick", "up"} <= words and words & _PACE):
        return Intent.FOLLOW
    if ("drop" in words and "off" in words) or ("let" in words and "out" in words and words & _US):
        return Intent.STOP
    return None


def _is_copular(c: tuple[str, ...], words: set[str]) -> bool:
    """A descriptive clause: a copula, no driving verb, no progressive ("the exit is on your left")."""
    if not words & _COPULA or words & _DIRECTIVE or words & _MODAL or c[0] in _COPULA or c[0] == "please":
        return False
    return not any(len(t) > 5 and t.endswith("ing") and t not in _ING_NOUNS for t in c)


def _bends(c: tuple[str, ...]) -> bool:
    """Whether the road itself bends in this clause ("the road curves left")."""
    return any(t in _BEND and any(s in _BEND_SUBJECT for s in c[:k]) for k, t in enumerate(c))


def _clause_mentions(c: tuple[str, ...], alt: bool, ctx: tuple[bool, bool, bool]) -> list[_Mention]:
    """Surviving (non-negated, highest-level) mentions of one clause."""
    words = set(c)
    if words & _ROAD_USERS and _third_party(c):  # another road user's maneuver: none of ours
        return [(Intent.STOP, _NOTICE, alt)] if _is_notice(c, words) else []
    other = _speed_or_drop_off(c, words) if words & _NO_MANEUVER else None
    if other is not None:
        return [(other, _STRONG if other is Intent.STOP else _WEAK, alt)]
    if not words & _TRIGGERS_OR_NEG:
        return [(Intent.STOP, _NOTICE, alt)] if _is_notice(c, words) else []
    neg, extra = _negation(c) if words & _NEGATOR_HEADS else ([False] * len(c), [])
    copula = _is_copular(c, words)
    if words & _PROHIBITED or (copula and words & _CLOSED) or ("not" in words and words & _PERMITTED):
        return []  # "turning right is prohibited", "left turns are not allowed", "left is closed"
    bend = bool(words & _BEND) and _bends(c)
    found = [(j, intent, _STRONG if intent is Intent.STOP else _WEAK) for j, intent in extra]
    for i, tok in enumerate(c):
        if tok in _TRIGGERS and not neg[i]:
            m = _mention(c, i, ctx, copula, bend)
            if m is not None:
                found.append((i, m[0], m[1]))
    if extra:
        found.sort(key=lambda f: f[0])
    if "or" in words:
        found = _drop_alternatives(c, found)
    if not found:
        return [(Intent.STOP, _NOTICE, alt)] if _is_notice(c, words) else []
    top = max(f[2] for f in found)
    sub_from = _subordinate_start(c) if words & _SUBORDINATE else len(c)
    return [(intent, lvl, alt or i > sub_from) for i, intent, lvl in found if lvl == top]


def _is_notice(c: tuple[str, ...], words: set[str]) -> bool:
    """A caution notice ("watch out for pedestrians", "stop sign ahead", "slow down", "yield")."""
    if words & _CAUTION or ("look" in words and "out" in words) or ("give" in words and "way" in words):
        return True
    if "slow" in words and ("down" in words or c[0] == "slow"):
        return True
    if words & _DECELERATE or (words & _SPEED and words & _LESS) or {"heads", "up"} <= words:
        return True  # "decelerate", "reduce your speed", "easy on the gas", "heads up"
    hazard = words & _HAZARD or words & _LIGHTS or ("stop" in words and "sign" in words)
    return bool(hazard and words & _APPROACH)


def _subordinate_start(c: tuple[str, ...]) -> int:
    """Index of the first subordinating word ("after", "before", "when", ...) of the clause."""
    return next(k for k, t in enumerate(c) if t in _SUBORDINATE)


def _drop_alternatives(c: tuple[str, ...], found: list[_Found]) -> list[_Found]:
    """Drop directions offered as alternatives ("turn left or right")."""
    drop: set[int] = set()
    for a, b in zip(found, found[1:]):
        gap = c[a[0] + 1 : b[0]]
        if a[1] != b[1] and a[2] == b[2] == _STRONG and "or" in gap and all(t in _OR_GAP for t in gap):
            drop.update((a[0], b[0]))
    return [f for f in found if f[0] not in drop] if drop else found


def _choose(mentions: list[_Mention]) -> Intent:
    """Apply the precedence rules of the module docstring to the mentions in text order."""
    pool = [(intent, lvl) for intent, lvl, sub in mentions if not sub] or [m[:2] for m in mentions]
    specific = [intent for intent, lvl in pool if lvl >= _MEDIUM]
    if specific:
        return specific[-1]
    if any(lvl == _WEAK for _, lvl in pool):
        return Intent.FOLLOW
    return Intent.STOP if pool else Intent.UNKNOWN  # only caution notices left


def _classify(tokens: tuple[str, ...]) -> Intent:
    words = set(tokens)
    ctx = (bool(words & _ROUNDABOUT), bool(words & _JUNCTION), bool(words & _HIGHWAY))
    mentions: list[_Mention] = []
    for clause, alt in _clauses(tokens):
        mentions.extend(_clause_mentions(clause, alt, ctx))
    return _choose(mentions)


@lru_cache(maxsize=65536)
def classify_intent(text: str) -> Intent:
    """Intent of one English navigation instruction (see the module docstring for the rules)."""
    return _classify(_tokens(text))
