"""The ``icrsumo`` command: one entry point, one thin subcommand per library job."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from . import __version__
from .errors import InputError


def _cmd_convert_routes(args: argparse.Namespace) -> int:
    from .convert import ConvertOptions, convert_routes
    from .resources import bundled_suites

    routes = Path(args.routes)
    if not routes.exists() and args.routes in bundled_suites():
        routes = bundled_suites()[args.routes]
    opts = ConvertOptions(
        coords=args.coords, traffic=args.traffic, net=args.net, xodr=args.xodr,
        net_dir=args.net_dir, max_snap=args.max_snap, seed=args.seed, warmup=args.warmup,
        workers=args.workers,
    )
    t0 = time.perf_counter()
    report = convert_routes(routes, Path(args.out), opts)
    dt = time.perf_counter() - t0
    print(
        f"{len(report.converted)} converted, {len(report.reused)} reused, "
        f"{len(report.failures)} failed in {dt:.1f} s -> {args.out}",
        file=sys.stderr,
    )
    for line in report.failures:
        print(line, file=sys.stderr)
    return 2 if report.failures else 0


def _cmd_generate(args: argparse.Namespace) -> int:
    from .instructions.generate import GenerateOptions, generate

    families = tuple(f for item in args.families for f in item.split(",") if f)
    llm = None
    if args.generator == "llm":
        from .instructions.llm import LLMConfig

        if not args.endpoint or not args.model:
            raise InputError("--generator llm", "", "needs --endpoint URL and --model NAME",
                             "give the chat-completions server and model")
        llm = LLMConfig(endpoint=args.endpoint, model=args.model,
                        cache_dir=Path(args.cache or Path(args.out) / "llm_cache"),
                        api_key=os.environ.get("ICRSUMO_LLM_API_KEY"))
    opts = GenerateOptions(families=families, k=args.k, seed=args.seed, templates=args.templates,
                           workers=args.workers, llm=llm)
    t0 = time.perf_counter()
    written, failures = generate(Path(args.scenarios), Path(args.out), opts)
    print(f"{len(written)} routes x (1 + {len(families)} x {args.k}) sequences, {len(failures)} failed "
          f"in {time.perf_counter() - t0:.1f} s -> {args.out}", file=sys.stderr)
    for line in failures:
        print(line, file=sys.stderr)
    return 2 if failures else 0


def _cmd_run_episode(args: argparse.Namespace) -> int:
    from .agents.registry import make_agent
    from .instructions.store import read_instruction_sets
    from .logs import result_to_dict, write_log
    from .metrics import score_episode
    from .runner import RunOptions, run_episode
    from .scenario import read_scenario

    sc = read_scenario(Path(args.scenario))
    sets = read_instruction_sets(Path(args.instructions))
    chosen = [s for s in sets if s.family == args.family and (s.k == args.k or args.family == "baseline")]
    if not chosen:
        have = sorted({f"{s.family}:{s.k}" for s in sets})
        raise InputError(args.instructions, f"{args.family} k={args.k}", "no such instruction set",
                         f"pick one of {', '.join(have[:6])}, ...")
    agent = make_agent(args.agent)
    log = run_episode(sc, chosen[0], agent, RunOptions(video=Path(args.video) if args.video else None))
    result = score_episode(log)
    if args.log:
        write_log(Path(args.log), log)
    r = result_to_dict(result)
    print(f"{sc.route_id} {args.agent} {args.family}:{chosen[0].k}  DS {r['ds']:.1f}  RC {r['rc']:.1f}  "
          f"IS {r['is']:.3f}  {result.termination} ({result.termination_class.value})  "
          f"infractions {[i.kind for i in result.infractions]}")
    return 0


def _split_list(items: list[str] | None) -> tuple[str, ...]:
    return tuple(x for item in items or [] for x in item.split(",") if x)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .agents.registry import DEFAULT_AGENT
    from .evaluate import EvalOptions, evaluate
    from .instructions.families import FAMILIES

    opts = EvalOptions(
        out=Path(args.out), suite=args.suite, agents=_split_list(args.agent) or (DEFAULT_AGENT,),
        families=_split_list(args.family) or FAMILIES, k=args.k, seed=args.seed,
        routes=_split_list(args.routes) or None, workers=args.workers, backend=args.backend,
        address=args.address, traffic=args.traffic, quiet=args.quiet, rollout_route=args.rollout_route,
    )
    t0 = time.perf_counter()
    summary = evaluate(opts)
    ep = summary["episodes"]
    print(f"{ep['done']} episodes done, {ep['crashed']} crashed, {time.perf_counter() - t0:.0f} s -> "
          f"{args.out}", file=sys.stderr)
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from .evaluate import report_only

    report_only(Path(args.out), quiet=args.quiet)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="icrsumo",
        description="Instruction-robustness benchmark for language-conditioned driving on SUMO.",
    )
    parser.add_argument("--version", action="version", version=f"icrsumo {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser(
        "convert-routes", help="leaderboard route XML -> runnable SUMO scenarios",
        description="Convert a leaderboard-style route file (or a bundled split: tiny, short, "
        "long, train) into SUMO scenarios with background traffic.",
    )
    p.add_argument("routes", help="route XML file, or the name of a bundled split")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--net", type=Path, help="use this .net.xml for every route")
    p.add_argument("--xodr", type=Path, help="convert this OpenDRIVE file (cached) for every route")
    p.add_argument("--net-dir", type=Path,
                   help="folder with <town>.net.xml or <town>.xodr per route town")
    p.add_argument("--coords", choices=["sumo", "carla"], default="sumo",
                   help="waypoint frame: sumo (default) or CARLA's left-handed frame")
    p.add_argument("--traffic", choices=["none", "light", "normal", "dense"], default="normal")
    p.add_argument("--max-snap", type=float, default=10.0,
                   help="farthest a waypoint may lie from a drivable lane (m, default 10)")
    p.add_argument("--seed", type=int, default=0,
                   help="base seed; each route's seed derives from it and the route id")
    p.add_argument("--warmup", type=float, default=20.0,
                   help="seconds of background traffic before the ego departs (default 20)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes (default: number of cores)")
    p.set_defaults(func=_cmd_convert_routes)

    g = sub.add_parser(
        "generate", help="baseline instructions + counterfactual variants per route",
        description="Write, per converted route, the baseline instruction sequence and K variant "
        "sequences per family (paraphrase, ambiguity, noise, misleading).",
    )
    g.add_argument("scenarios", help="folder written by convert-routes (or one scenario folder)")
    g.add_argument("--out", required=True, help="output folder")
    g.add_argument("--families", nargs="+", default=["paraphrase,ambiguity,noise,misleading"],
                   help="families, space or comma separated (default: all four)")
    g.add_argument("--k", type=int, default=8, help="variants per family (default 8)")
    g.add_argument("--seed", type=int, default=2026, help="seed of all draws (default 2026)")
    g.add_argument("--templates", type=Path, help="folder with your own template banks")
    g.add_argument("--generator", choices=["templates", "llm"], default="templates")
    g.add_argument("--endpoint", help="OpenAI-compatible base URL, e.g. http://127.0.0.1:8000/v1")
    g.add_argument("--model", help="model name for --generator llm")
    g.add_argument("--cache", type=Path, help="LLM answer cache (default OUT/llm_cache)")
    g.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    g.set_defaults(func=_cmd_generate)

    e = sub.add_parser(
        "run-episode", help="drive one closed-loop episode and score it",
        description="Run one scenario with one instruction sequence and one agent in SUMO; print "
        "its Leaderboard scores; optionally write the episode log and a BEV video.",
    )
    e.add_argument("scenario", help="a scenario folder written by convert-routes")
    e.add_argument("--instructions", required=True, help="the route's file written by generate")
    e.add_argument("--family", default="baseline",
                   choices=["baseline", "paraphrase", "ambiguity", "noise", "misleading"])
    e.add_argument("--k", type=int, default=0, help="variant index (default 0)")
    e.add_argument("--agent", default="instruction-follower",
                   help="route-oracle or instruction-follower (default)")
    e.add_argument("--log", help="write the episode log (JSON) here")
    e.add_argument("--video", help="write a BEV video with the instruction overlaid (.mp4)")
    e.set_defaults(func=_cmd_run_episode)

    v = sub.add_parser(
        "evaluate", help="the paired ICR protocol: baseline vs counterfactual instructions",
        description="Run every agent on every route with the baseline instructions and K variants "
        "of each family (same scenario, seed, traffic), store each episode at once (resumable), "
        "and write summary.json, tables and figures.",
    )
    v.add_argument("--suite", default="tiny",
                   help="tiny (default), short, long, a route XML file or a convert-routes folder")
    v.add_argument("--agent", action="append",
                   help="built-in name, module:Class or path/file.py:Class (repeatable; default "
                   "instruction-follower)")
    v.add_argument("--family", action="append",
                   help="paraphrase, ambiguity, noise, misleading (repeatable; default all four)")
    v.add_argument("--k", type=int, default=8, help="variants per family (default 8)")
    v.add_argument("--seed", type=int, default=2026, help="seed of the variant draws (default 2026)")
    v.add_argument("--routes", action="append", help="only these route ids (comma separated)")
    v.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes, one SUMO each (default: number of cores)")
    v.add_argument("--backend", default="local", help="local (default) or ray")
    v.add_argument("--address", help="Ray cluster address for --backend ray")
    v.add_argument("--traffic", choices=["none", "light", "normal", "dense"], default="normal")
    v.add_argument("--out", default="icr_out", help="output folder (default icr_out)")
    v.add_argument("--rollout-route", help="route of the paired rollout figure (default: the first)")
    v.add_argument("--quiet", action="store_true", help="no progress bar or table")
    v.set_defaults(func=_cmd_evaluate)

    r = sub.add_parser("report", help="rebuild summary, tables and figures of an evaluation folder")
    r.add_argument("out", help="the --out folder of icrsumo evaluate")
    r.add_argument("--quiet", action="store_true")
    r.set_defaults(func=_cmd_report)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; bad input gives one line on stderr and exit status 2."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as err:
        print(f"icrsumo: error: {err.line()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("icrsumo: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
