"""The intent classifier's vocabulary: the word lists its rules read and the tables its spelling
correction uses (data only; :mod:`icrsumo.instructions.spelling` and
:mod:`icrsumo.instructions.rules` read them, :mod:`icrsumo.instructions.intent` documents the rules).

Most names are sets of canonical tokens, named for the slot where a rule looks for them: ``_PREV``
words stand just before the word a rule examines, ``_NEXT`` words just after it, ``_SKIP`` words
are stepped over.
"""

from __future__ import annotations


def _words(text: str) -> frozenset[str]:
    return frozenset(text.split())


# --- rule vocabulary -----------------------------------------------------------------------------

LEFT_RIGHT = frozenset({"left", "right"})
LANE = _words("lane lanes")
DETS = _words("the a an your this that my our its current same next")
ORDINALS = {"first": 1, "second": 2, "third": 3, "fourth": 4, "fifth": 5, "sixth": 6, "seventh": 7}
NUMBER_WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7}
ROUNDABOUT = _words("roundabout roundabouts rotary circle")
HIGHWAY = _words(
    "highway highways freeway freeways motorway motorways expressway interstate autobahn turnpike "
    "parkway tollway thruway autoroute beltway carriageway"
)
ROAD = HIGHWAY | _words(
    "road roads street streets st rd avenue ave boulevard blvd route lane path bridge tunnel track"
)
JUNCTION = _words(
    "junction junctions intersection intersections crossroads crossroad crossing crossings light "
    "lights signal signals roundabout corner"
)
COMPASS = _words(
    "north south east west northeast northwest southeast southwest northbound southbound eastbound "
    "westbound"
)
FOLLOW_CONTEXT = ROAD | COMPASS | _words("along down up onto on forward forwards")
MOTION = _words(
    "go goes going drive drives driving head heads heading travel traveling travelling move moving "
    "cruise cruising ride roll rolls rolling"
)
BARE_MOTION_PREV = _words("just please now simply then and so keep")
ROAD_VERBS = _words("enter entering join joining take cross crosses")
FOLLOW_VERBS = _words("follow follows continue continues continuing proceed proceeds proceeding")
KEEP_NEXT = _words(
    "going driving moving rolling cruising heading on along ahead in to following forward traveling "
    "travelling the this your"
)
STAY_NEXT = _words("on in along with within the this your behind")
DIRECTIVE = _words(
    "turn turning turns go going goes take taking make making keep keeping bear veer head heading drive "
    "driving move moving change changing switch merge merging stay staying continue continuing follow "
    "following proceed exit exiting enter entering stop stopping use get pull cross hang steer swing "
    "shift wait park halt brake carry leave join remain travel"
)
TURN_NOUN_NEXT = _words("turn turns turning exit ramp fork hander")
DIR_PREV_MOTION = _words("go going goes head heading drive driving then and")
DIR_PREV = DIR_PREV_MOTION | _words(
    "turn turning turns bear bearing veer keep hang steer swing take make the a an to slight slightly fork "
    "sharp sharply hard your far move merge shift switch change lane lanes next first second third "
    "fourth or not never no quick"
)
RIGHT_ADVERB_NEXT = _words("through across past ahead along away")
RIGHT_INTENSIFIED = _words(
    "now away here there after before behind next past then when as until ahead beside by around "
    "where outside under over up down along this that back through across"
)
RIGHT_PLACE_NEXT = _words("at on in into onto")
STATIC_PREV = _words("stop halt wait park parked is are was be it located sits lies just pull stay left")
PREPOSITIONS = _words("to into onto in the")
LEFT_NOT_DIR_PREV = _words(
    "you we they i he she have has had was were been nothing anything something meters metres "
    "miles km kilometers kilometres feet ft yards m mi minutes seconds time just"
)
LANE_FWD_SKIP = _words("hand most side two one both of the 2 3 three")
LANE_VERBS = _words(
    "change changing switch switching shift shifting merge merging move moving get swap overtake"
)
LANE_VERB_SKIP = _words("over across to into the your one a lane lanes back")
LANE_KEEP = _words("keep stay drive remain stick overtake pass")
LANE_BACK_BLOCK = _words("turn turning take exit go bear veer hang") | JUNCTION
ROADISH_BEFORE_ON = _words(
    "exit exits ramp road roads street streets turn turning turnoff lane lanes one avenue st rd ave "
    "entrance junction first second third fourth next fork driveway lot garage"
)
PASS = _words("pass passing past passes by")
COPULA = _words("is are was were be been will lies lie located sits appears")
LOCATIVE_SKIP = COPULA | _words("coming up approaching ahead soon just")
MODAL = _words("need needs should must want wants have has got ought")
BEND = _words("curves curve bends bend winds sweeps turns veers swings")
BEND_SUBJECT = ROAD | _words("it")
ROUND = _words("round around")
BEND_WORDS = BEND | ROUND
TRAVERSE = _words("through across over past")
AHEAD_VERBS = MOTION | _words("continue proceed carry keep")
#: other road users: a clause opening with one of them and a verb of its own asks nothing of the ego
ROAD_USERS = _words(
    "car cars truck trucks lorry lorries bus buses van vans cyclist cyclists bike bikes bicycle bicycles "
    "biker bikers motorbike motorbikes motorcycle motorcycles scooter scooters taxi taxis cab vehicle "
    "vehicles pedestrian pedestrians tractor tractors driver drivers ambulance tram trams suv jeep sedan "
    "coach someone somebody"
)
THIRD_DETS = _words("that those these some another every")
#: words of a place after the road user ("ahead", "behind you", "in front of you", "in the left lane")
PLACE_WORDS = _words("ahead behind in front of you us the left right lane on your next to beside there here "
                      "black white red blue grey gray silver green yellow big small")
THIRD_VERBS = _words(
    "is are was were will would wants want seems seem has have keeps plans intends starts tries about "
    "turns turning changes changing merges merging overtakes overtaking goes going pulls pulling moves moving"
)
#: a fork's place ("stay right at the fork / the Y-junction / where it splits")
FORK_PLACE = JUNCTION | _words("fork forks split y")
FASTER = _words("accelerate accelerating faster quicker")
#: things named "speed ...", no call to speed up ("a speed bump coming up")
SPEED_THINGS = _words("bump bumps hump humps camera cameras trap traps limit limits")
PACE = _words("pace speed")
US = _words("me us")
NO_MANEUVER = FASTER | _words("speed drop let pick foot floor hurry step gun")
STOP_HEADS = _words(
    "stop stops stopping halt standstill brake brakes braking wait waiting park pull stand stay hold"
)
EXIT_HEADS = _words("exit exits ramp leave leaving off quit quits quitting")
EXIT_CONTEXT = HIGHWAY | _words("exit exits ramp")
TRAVERSE_SKIP = DETS | _words(
    "next upcoming first second 4 four way traffic stop big main t coming approaching following "
    "forthcoming ensuing subsequent imminent nearest"
)
CROSS_SKIP = TRAVERSE_SKIP | _words("over at")
STOP_NOUN_NEXT = _words("sign signs line lines light lights bar signal signals marker street")
STOP_NOUN_PREV = _words("bus truck rest pit tram taxi next last first non one way")
STOP_COME = _words("come comes coming bring make pull roll")
STOP_ADJ = _words("a the complete full sudden abrupt quick emergency gentle rolling dead")
PARK_PREV = _words("please and then now just to can should must safely")
PARK_NEXT = _words("here there on at by near behind beside in your the")
PULL_STOP = _words("over up aside in")
NOT_ROAD_EXIT = _words("parking car garage lot building driveway station vehicle tunnel mall park area")
NEGATORS = _words(
    "not no never avoid avoiding skip skipping ignore ignoring forget cancel without disregard nor"
)
NEG_FILLER = _words("to do be you of than")
# "no" that negates nothing: "no sweat, ...", "no problem", "no big deal", "no worries"
NO_IDIOM = _words("sweat problem problems worries worry biggie big doubt rush hurry pressure stress fuss")
NEG_CANCEL = _words("forget miss fail neglect hesitate ignore skip")
NEG_MOTION = _words("move go proceed continue drive moving going driving")
NEG_MOTION_NEXT = _words("yet further forward anymore any until now here beyond") | {""}
SPLIT = _words("and but then so however actually otherwise instead rather because since")
PROHIBITED = _words("prohibited forbidden banned illegal disallowed")
PERMITTED = _words("allowed permitted possible legal")
CLOSED = _words("closed blocked")
ING_NOUNS = _words(
    "parking building buildings crossing crossings morning evening nothing something anything "
    "everything turning ceiling during string spring sibling"
)
CAUTION = _words(
    "watch caution careful carefully beware alert attention mind yield yielding obey cautious aware mindful "
    "wary vigilant attentive"
)
# slowing down is a caution notice too ("decelerate", "reduce your speed", "ease off the gas")
DECELERATE = _words("decelerate decelerates decelerating deceleration slower slowly")
SPEED = _words("speed speeds velocity pace gas throttle accelerator")
LESS = _words("reduce reduces reducing reduction lower lowering decrease decreasing cut drop ease easy down")
HAZARD = _words(
    "pedestrian pedestrians people cyclist cyclists bike bikes bicycle children kids animal animals deer "
    "crosswalk crossing obstacle obstacles hazard roadworks signal signals bump bumps hump humps school zone "
    "camera cameras narrows narrowing"
)
LIGHTS = _words("light lights")
APPROACH = _words("ahead approaching coming upcoming red near")
SUBORDINATE = _words("before after once when whenever until till while as if unless")
# starting to drive ("commence driving", "begin the trip", "set off", "get moving", "pull away")
START_VERBS = _words("start starts begin begins commence commences commencing initiate initiates")
START_OBJECTS = _words("driving drive moving going journey trip route rolling motion ride")
SET_OFF = {"set": _words("off out forth"), "get": _words("moving going rolling started"),
            "pull": _words("away"), "press": _words("on ahead forward onward onwards"),
            "push": _words("on ahead forward onward onwards")}
# keeping one's course ("maintain your course", "hold your heading"): FOLLOW, or STRAIGHT when it
# is kept at / through a junction ("maintain your direction at the intersection")
COURSE_KEEP = _words(
    "keep keeps keeping maintain maintains maintaining preserve preserves preserving hold holds holding "
    "stay stays staying remain remains remaining continue continues continuing follow follows"
)
COURSE = _words("course heading direction trajectory bearing line lane")
COURSE_SKIP = DETS | _words("present existing original")
AT_JUNCTION = _words("at through across past over")
EXIT_BY = _words("at by on via using")
#: "straight" opening a clause before these means at once ("and straight after that, a right")
STRAIGHT_AFTER = _words("after afterwards")
#: what a roundabout's exit is called beside "exit" ("the second turning", "the first opportunity")
EXIT_NOUNS = _words("one turning turn turnoff road opportunity street way")
# what "don't ..." asks for when it keeps the current road ("do not deviate from this route")
DEVIATE = _words("deviate deviating stray straying swerve diverge diverging depart departing")
OR_GAP = _words("or either to the go turn")
BOUNDARY = frozenset({",", "."})
# --- commands as people say them: conditions, continuations, back-references ------------------
#: base-form verbs that open an imperative after a condition ("once clear turn left")
IMPERATIVE = _words(
    "turn go take make keep bear veer head drive move change switch merge stay continue follow proceed "
    "exit enter stop use get pull cross hang steer swing shift wait park halt brake carry leave join "
    "remain travel"
)
#: words before a base-form verb that make it no imperative ("when you turn", "if you can go")
NOT_IMPERATIVE_PREV = DETS | _words(
    "you we i they it he she one someone to can could will would should must may might do does did not "
    "shall need needs have has let us"
)
#: imperatives that end a negation's scope after the negated verb ("don't overtake here stay in
#: your lane"); verbs that double as nouns (turn, exit, stop, park, change) are not among them
SCOPE_VERBS = _words(
    "go keep stay continue follow proceed head bear veer pull merge take drive carry hang move remain stick"
)
#: verbs of saying: the imperative after them is reported, not given
SAYING = _words("say says saying said tell tells telling told read reads reading")
#: where a clause about another road user turns to the ego without punctuation ("... wait behind
#: it", "... you turn right")
EGO_VERBS = IMPERATIVE | _words("let overtake pass slow give yield")
EGO_SUBJECTS = _words("you we")
#: polite asides, no part of the command (they would read as a negation or a caution)
ASIDES = tuple(tuple(a.split()) for a in (
    "if you do not mind", "if you would not mind", "if it is not too much trouble"))
#: fillers at the ends of a clause ("please", "now", "ok"): no part of what it says
FILLERS = _words("please now thanks thank ok so just well oh hey asap")
#: a first clause that is only "Right," before a command of its own is a discourse marker
#: ("Right, carry on down the high street")
DISCOURSE_RIGHT = (("right",), ("right", "then"), ("right", "so"), ("ok", "right"), ("right", "ok"))
#: "after that", "before this": a sequence, not a condition
SEQUENCE = _words("after before")
#: "the left one is ending", "the right lane is closed": a side heading a subject
DESCRIBED_SKIP = _words("one lane lanes hand")
#: "right after the church" opening a clause with no verb is a turn there
RIGHT_PLACED = _words("after before past")
NOT_YET = _words("yet now here") | {""}
#: "move into it", "get over to it"
INTO = _words("into to in onto")
#: a condition that is only a pronoun ("after that, head left")
THAT = _words("that this which")
#: subordinators whose condition comes before the maneuver ("wait ... before you turn left")
DEFERRING = _words("before until till")
#: negations of a maneuver that defer it rather than refuse it ("don't turn right until ...")
NEG_DEFER = _words("until till")
#: a clause opened by these after a maneuver may be its continuation ("... and continue straight")
CONTINUATION_OPENERS = _words("and then")
CONTINUATION_HEADS = _words("continue continuing carry keep proceed")
#: a clause that points back at a negated maneuver ("not the first right, the second one")
BACK_REFERENCE = frozenset(ORDINALS) | _words("next other following")
#: passing another road user on a side is a lane change ("overtake the tractor on the right")
OVERTAKE_VERBS = _words("overtake overtaking pass passing past around round")
OVERTAKEN = _words("it them him her")
#: yielding ("let them pass", "let the bus through"), a STOP
LET_YIELD = _words("pass through by past cross go first")
LET_OUT = _words("out off")
#: leaving a highway at a numbered junction or slip road ("come off at junction 12")
OFF_VERBS = _words("come get pull turn")
SLIP = _words("slip")
#: driving faster in idioms ("put your foot down")
FASTER_IDIOMS = tuple(map(_words, (
    "foot down", "floor it", "hurry up", "step on it", "gun it", "pick it up")))
#: caution notices in two words ("look out", "give way", "heads up", "keep an eye out")
CAUTION_PAIRS = tuple(map(_words, ("look out", "give way", "heads up", "eye out", "eyes out", "eyes peeled",
                                    "it easy")))
#: a clause that is only a side ("on the right") after one about the turn / exit names its side
SIDE_PREPOSITIONS = _words("on to")
TURN_NOUNS = _words("turn turning turnoff exit")
#: an exit driven past, not taken ("stay on the motorway past this exit")
PASSED = _words("past beyond")
#: slowing down ("ease off", "ease up")
EASE_OFF = _words("off up")
HEADS = LEFT_RIGHT | LANE | _words("straight stop halt exit ramp follow continue proceed brake wait park")

# --- spelling (normalize) ------------------------------------------------------------------------

#: keywords a misspelt word is corrected to (in this order on ties)
FUZZY_TARGETS: tuple[str, ...] = (
    "light", "left", "right", "straight", "turn", "turning", "lane", "lanes", "follow", "continue", "stop",
    "exit", "roundabout", "junction", "intersection", "crossroads", "crossing", "change", "switch", "merge",
    "proceed", "ahead", "road", "street", "highway", "freeway", "motorway", "through", "across", "cross",
    "halt", "brake", "wait", "pull", "keep", "stay", "going", "driving", "instead", "ignore", "never",
    "first", "second", "third", "fourth", "traffic", "carry", "ramp", "drive", "following",
    "start", "stick", "maintain", "maintaining", "course", "direction", "deviate", "commence",
)
#: more targets, after those (issue 45): the rule words that, added one at a time, read more of the
#: commands of tests/data/commands/ right under the noise family's typos and changed no bank text's
#: class (tests/instructions/test_intent_commands.py checks both), in order of that gain
FUZZY_TARGETS += (
    "the", "over", "move", "careful", "speed", "until", "come", "floor", "coming", "watch", "yield",
    "along", "down", "heading", "car", "hurry", "way", "quick", "slower", "here", "lights", "pass",
    "truck", "behind", "foot", "next", "past", "reduce", "reduces", "decelerates", "fork", "park",
    "slip", "slowly", "around", "eye", "hang", "hold", "mind", "that", "drop", "overtake", "put",
    "there", "bearing", "carefully", "hand", "its", "obey", "round", "sharp", "speeds", "swing", "two",
    "upcoming", "wary", "your", "give", "cyclist", "cyclists", "need", "from", "wants",
)

ALIASES: dict[str, tuple[str, ...]] = {
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
QWERTY_NEIGHBOURS = {
    "q": "wa", "w": "qeas", "e": "wrsd", "r": "etdf", "t": "ryfg", "y": "tugh", "u": "yihj", "i": "uojk",
    "o": "ipkl", "p": "ol", "a": "qwsz", "s": "awedxz", "d": "serfcx", "f": "drtgvc", "g": "ftyhbv",
    "h": "gyujnb", "j": "huikmn", "k": "jiolm", "l": "kop", "z": "asx", "x": "zsdc", "c": "xdfv",
    "v": "cfgb", "b": "vghn", "n": "bhjm", "m": "njk",
}
CONTRACTION_STEM = {"wo": "will", "ca": "can", "sha": "shall"}
CONTRACTION_TAIL = {"'re": "are", "'ll": "will", "'ve": "have", "'d": "would", "'m": "am"}
IS_PRONOUNS = _words("it there that here what where who he she")
#: in a direction slot ("turn _"), homophones of a side, and the words that open a slot
SLOT_HOMOPHONES = {"rite": "right", "write": "right", "wright": "right", "strait": "straight"}
SLOT_PREV = _words("turn turning go bear veer keep hang slight sharp hard")

# Real words never spell-corrected: function words, driving vocabulary and every common word within
# the edit budget of a keyword (false friends).
STOP_LIST = _words(
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

#: every word the rules read; with the stop list, the words never spell-corrected
RULE_WORDS = (
    LEFT_RIGHT | LANE | DETS | ROUNDABOUT | ROAD | JUNCTION | COMPASS | FOLLOW_CONTEXT
    | MOTION | FOLLOW_VERBS | KEEP_NEXT | STAY_NEXT | DIRECTIVE | TURN_NOUN_NEXT | DIR_PREV
    | RIGHT_INTENSIFIED | RIGHT_PLACE_NEXT | STATIC_PREV | LEFT_NOT_DIR_PREV | LANE_FWD_SKIP
    | LANE_VERBS | LANE_VERB_SKIP
    | LANE_KEEP | ROADISH_BEFORE_ON | PASS | COPULA | BEND | TRAVERSE | TRAVERSE_SKIP
    | STOP_NOUN_NEXT | STOP_NOUN_PREV | STOP_COME | STOP_ADJ | PARK_PREV | PARK_NEXT
    | PULL_STOP | NOT_ROAD_EXIT | NEGATORS | NEG_CANCEL | NEG_MOTION | NEG_MOTION_NEXT
    | SPLIT | SUBORDINATE | HEADS | frozenset(ORDINALS) | frozenset(NUMBER_WORDS)
    | _words("instead rather of than standstill still put hold position u around back stand sure")
    | CAUTION | DECELERATE | SPEED | LESS | START_VERBS | START_OBJECTS | frozenset(SET_OFF)
    | frozenset().union(*SET_OFF.values()) | COURSE_KEEP | COURSE | COURSE_SKIP | DEVIATE
    | _words("heads quit quits quitting leave leaves") | NO_IDIOM
    | IMPERATIVE | DEFERRING | CONTINUATION_HEADS | OVERTAKE_VERBS | LET_YIELD | OFF_VERBS | SLIP
    | _words("foot eye eyes peeled floor trouble") | SIDE_PREPOSITIONS | TURN_NOUNS | PASSED | EASE_OFF
    | FILLERS | SCOPE_VERBS | EGO_VERBS | SAYING | EXIT_NOUNS | STRAIGHT_AFTER | SEQUENCE | INTO | ROUND
    | _words("bump bumps hump humps zone school gun step carriageway narrows narrowing") | SPEED_THINGS
    | DESCRIBED_SKIP | RIGHT_PLACED | NOT_YET | LET_OUT | _words("ending ends ended")
)
KNOWN = STOP_LIST | RULE_WORDS | frozenset(FUZZY_TARGETS)
NO_SLOT_FIX = KNOWN - frozenset(SLOT_HOMOPHONES)

# --- mention and negation heads ------------------------------------------------------------------

NEGATOR_HEADS = NEGATORS | _words("instead rather stop")
# Tokens that can head a mention (see ``rules._mention`` and ``rules._follow``); any other token is skipped.
TRIGGERS = (
    LEFT_RIGHT | TRAVERSE | MOTION | FOLLOW_VERBS | ROAD_VERBS | frozenset(ORDINALS)
    | _words(
        "straight stop stops stopping halt standstill brake brakes braking wait waiting park pull stand "
        "stay stays hold exit exits ramp leave leaving off ahead cross crosses merge merging resume carry "
        "keep keeps remain remains maintain stick start begin get quit quits quitting"
    )
    | START_VERBS | frozenset(SET_OFF) | COURSE_KEEP
)
TRIGGERS_OR_NEG = TRIGGERS | NEGATOR_HEADS
