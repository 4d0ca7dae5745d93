"""``icrsumo run-episode``: drive one closed-loop episode and score it.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from icrsumo.core.defaults import DEFAULT_AGENT
from icrsumo.core.errors import InputError
from icrsumo.core.vocab import Family

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo run-episode``."""
    e = sub.add_parser(
        "run-episode", help="drive one closed-loop episode and score it",
        description="Run one scenario with one instruction sequence and one agent in SUMO; print "
        "its Leaderboard scores; optionally write the episode log and a BEV video.",
    )
    e.add_argument("scenario", help="a scenario folder written by convert-routes")
    e.add_argument("--instructions", required=True, help="the route's file written by generate")
    e.add_argument("--family", default="baseline",
                   choices=[str(f) for f in Family])
    e.add_argument("--k", type=int, default=0, help="variant index (default 0)")
    e.add_argument("--agent", default=None,
                   help="built-in name, module:Class, file.py:Class or remote:URL (default: the "
                   f"default agent of evaluate, {DEFAULT_AGENT})")
    e.add_argument("--log", help="write the episode log (JSON) here")
    e.add_argument("--video", help="write a BEV video with the instruction overlaid (.webm: VP8, plays in "
                   "browsers; .mp4: MPEG-4 Part 2; .avi: Motion JPEG)")
    e.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo run-episode``; its exit status."""
    from icrsumo.agents.registry import DEFAULT_AGENT, make_agent
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.results.logs import result_to_dict, write_log
    from icrsumo.scoring import score_episode
    from icrsumo.sim.callbacks import VideoRecorder
    from icrsumo.world.scenario import read_scenario

    from ..api import run_episode

    sc = read_scenario(Path(args.scenario))
    sets = read_instruction_sets(Path(args.instructions))
    for option, value in (("--log", args.log), ("--video", args.video)):
        if value is not None and (not str(value).strip() or Path(value).is_dir()):
            raise InputError(option, str(value), "is a folder (or empty), not a file", "give a file path")
    chosen = [s for s in sets if s.family == args.family and (s.k == args.k or args.family == "baseline")]
    if not chosen:
        have = sorted({f"{s.family}:{s.k}" for s in sets})
        raise InputError(args.instructions, f"{args.family} k={args.k}", "no such instruction set",
                         f"pick one of {', '.join(have[:6])}, ...")
    args.agent = args.agent or DEFAULT_AGENT
    agent = make_agent(args.agent)
    callbacks = [VideoRecorder(Path(args.video))] if args.video else ()
    try:
        log = run_episode(sc, chosen[0], agent, callbacks=callbacks)
    except (InputError, OSError, KeyboardInterrupt):
        raise
    except Exception as err:  # the agent (or the simulator) failed: one line, as evaluate stores it
        from icrsumo.core.errors import describe

        why = " ".join(describe(err).split())[:300]
        raise InputError("--agent", args.agent, f"the episode failed: {why}",
                         f"fix the agent (icrsumo check-agent {args.agent} finds such problems)") from None
    result = score_episode(log)
    if args.log:
        write_log(Path(args.log), log)
    r = result_to_dict(result)
    print(f"{sc.route_id} {args.agent} {args.family}:{chosen[0].k}  DS {r['ds']:.1f}  RC {r['rc']:.1f}  "
          f"IS {r['is']:.3f}  {result.termination} ({result.termination_class.value})  "
          f"infractions {[str(i.kind) for i in result.infractions]}")
    return 0
