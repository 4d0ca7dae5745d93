"""Errors name fields, not command-line options: the library's InputErrors carry the field
they are about (:class:`icrsumo.core.errors.Field`); the Python API names it by its keyword, the
command line by its option (one table in :mod:`icrsumo.app.cli.options`); no module but the command
line's (icrsumo/app/cli/, icrsumo/cli.py) names an option in an error's text; ``icrsumo.run_episode``
refuses what ``icrsumo run-episode`` refuses; the parser is one small module per subcommand."""

from __future__ import annotations

import argparse
import ast
import inspect
import json
import pickle
import re
import shutil
from pathlib import Path

import pytest

import icrsumo
import icrsumo.app.cli
from icrsumo.app.cli import options
from icrsumo.app.cli.main import build_parser, main
from icrsumo.core.errors import Field, InputError
from icrsumo.core.resources import bundled_suites

PACKAGE = Path(icrsumo.__file__).parent
#: a command-line option in a text
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
#: what may precede an option in the same text: a whole command line (``icrsumo collect --out
#: DIR``, ``pip install --no-deps``), valid wherever the text is read
COMMAND = re.compile(r"\b(icrsumo [a-z][a-z-]*|pip install)\b")
#: texts that are no error and that the library shows as they are (``icrsumo list agents``'s
#: descriptions, check-agent's report), with the option they name
NOT_ERRORS = {("agents/registry.py", "--augment-instructions")}


def _docstrings(tree: ast.AST) -> set[int]:
    kinds = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
    return {id(node.body[0].value) for node in ast.walk(tree) if isinstance(node, kinds) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}


def _skipped(tree: ast.AST) -> set[int]:
    """The strings that are no message: the arguments of another program's command line
    (``--option`` words in a list or tuple). Notes are messages too (:func:`icrsumo.core.errors.note`
    names fields in the reader's words)."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.List, ast.Tuple)):
            skip |= {id(e) for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)
                     and re.fullmatch(r"--[\w.-]+", e.value)}
    return skip


def _options_named(source: str, rel: str) -> list[str]:
    """``file:line: option ...`` for every option that a text of the module ``rel`` (its
    ``source``) names."""
    tree = ast.parse(source)
    skip = _docstrings(tree) | _skipped(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.left, ast.Constant) and node.left.value == "--":
            found.append(f"{rel}:{node.lineno}: '--' + ...")  # an option made from a field's name
        if not isinstance(node, ast.Constant) or not isinstance(node.value, str) or id(node) in skip:
            continue
        for m in OPTION.finditer(node.value):
            if not COMMAND.search(node.value[:m.start()]) and (rel, m.group(0)) not in NOT_ERRORS:
                found.append(f"{rel}:{node.lineno}: {m.group(0)} in {node.value[:80]!r}")
    return found


#: the command line's modules, which name options
CLI = sorted((PACKAGE / "app" / "cli").glob("*.py"))


def test_no_module_but_the_cli_names_an_option_in_an_error():
    modules = [p for p in sorted(PACKAGE.rglob("*.py")) if p not in CLI]
    assert len(modules) > 50
    assert [line for p in modules for line in _options_named(p.read_text(encoding="utf-8"),
                                                              p.relative_to(PACKAGE).as_posix())] == []


def test_the_scan_finds_an_option_in_a_fix():
    """The scan above sees an option in a raise, in a fix kept in a variable, in a default and
    built from a field's name; not in a command line or another program's arguments."""
    found = _options_named('fix = "use another --out folder"\n'
                           'def f(option="--seed"):\n'
                           '    raise ValueError(f"{option}: give --k", "--" + "workers")\n'
                           'ok = ["--seed", "1"], "rerun icrsumo collect --out DIR"\n', "probe.py")
    assert sorted(line.split(": ", 1)[1].split(" in ")[0] for line in found) == [
        "'--' + ...", "--k", "--out", "--seed"]


def test_python_names_keywords_and_the_command_line_names_options(tmp_path, capsys):
    """One error, in each reader's words: the field it is about and a field its fix mentions;
    a field whose option another command spells otherwise (generate --families)."""
    with pytest.raises(InputError) as err:
        icrsumo.evaluate(out=tmp_path / "o", address="ray://x")
    assert str(err.value) == "address: ray://x: is for the ray backend (fix: add backend ray)"
    assert err.value.field == "address"
    assert main(["evaluate", "--out", str(tmp_path / "o"), "--address", "ray://x"]) == 2
    assert capsys.readouterr().err == ("icrsumo: error: --address: ray://x: is for the ray backend "
                                       "(fix: add --backend ray)\n")

    with pytest.raises(InputError, match=r"^families: nope: unknown family"):
        icrsumo.evaluate(out=tmp_path / "o", families="nope")
    assert main(["evaluate", "--out", str(tmp_path / "o"), "--family", "nope"]) == 2
    assert capsys.readouterr().err.startswith("icrsumo: error: --family: nope: unknown family")
    assert main(["generate", str(tmp_path), "--out", str(tmp_path / "g"), "--families", "nope"]) == 2
    assert capsys.readouterr().err.startswith("icrsumo: error: --families: unknown family nope")
    assert not (tmp_path / "o").exists() and not (tmp_path / "g").exists()


def test_an_error_keeps_its_fields_across_processes():
    err = InputError(Field("rollout_route"), "r9", "not a route of this evaluation",
                     f"use one of the {Field('routes')}")
    back = pickle.loads(pickle.dumps(err))
    assert back.field == "rollout_route" and str(back) == str(err)
    assert str(back) == "rollout_route: r9: not a route of this evaluation (fix: use one of the routes)"
    assert back.line(options.names("evaluate")) == ("--rollout-route: r9: not a route of this evaluation "
                                                 "(fix: use one of the --routes)")
    # a file is not a field, and a line given whole is kept as it is
    assert InputError(Path("a/routes.xml"), "route 1", "bad").field is None
    assert InputError.of_line("a: b: c").line(options.names("evaluate")) == "a: b: c"


def _other_route(instr: Path, tmp: Path) -> Path:
    doc = json.loads(instr.read_text(encoding="utf-8"))
    doc["route_id"] = "tiny_001"
    path = tmp / "other.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def _bad_manifest(sc_dir: Path, tmp: Path) -> Path:
    """A copy of the scenario (with its convert-routes folder) whose manifest names an edge its
    network does not have."""
    shutil.copytree(sc_dir.parents[1], tmp / "conv")
    copy = tmp / "conv" / sc_dir.relative_to(sc_dir.parents[1])
    doc = json.loads((copy / "scenario.json").read_text(encoding="utf-8"))
    doc["ego"]["edges"][0] = "no_such_edge"
    (copy / "scenario.json").write_text(json.dumps(doc), encoding="utf-8")
    return copy


@pytest.mark.parametrize("case, python, command_line", [
    ("other route", "instruction_set: route 'tiny_001': is not a sequence of the scenario's route "
     "'tiny_003'", "--instructions: route 'tiny_001': is not a sequence of the scenario's route 'tiny_003'"),
    ("bad manifest", "ego.edges[0]: edge 'no_such_edge' is not a car edge",
     "ego.edges[0]: edge 'no_such_edge' is not a car edge"),
])
def test_run_episode_refuses_what_the_command_line_refuses(cache, tmp_path, capsys, case, python,
                                                           command_line):
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets

    sc_dir, instr = bundled_route("tiny_003")
    if case == "other route":
        instr = _other_route(instr, tmp_path)
    else:
        sc_dir = _bad_manifest(sc_dir, tmp_path)
    log = tmp_path / "ep.json"
    assert main(["run-episode", str(sc_dir), "--instructions", str(instr), "--agent", "route-oracle",
                 "--log", str(log)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and command_line in err[0] and not log.exists(), err
    with pytest.raises(InputError) as raised:
        icrsumo.run_episode(sc_dir, read_instruction_sets(instr)[0], "route-oracle")
    assert python in str(raised.value)


def test_the_parser_is_one_small_module_per_subcommand(capsys):
    """Every subcommand is its own module of :data:`icrsumo.app.cli.SUBCOMMANDS`, whose functions are
    each under 120 lines, and the bundled suites are named from the installation, never written
    out in the CLI."""
    added = []
    for module in icrsumo.app.cli.SUBCOMMANDS:
        sub = argparse.ArgumentParser().add_subparsers()
        module.add(sub)
        assert len(sub.choices) == 1, module.__name__  # one subcommand per module
        added += sub.choices
    assert added == list(build_parser()._subparsers._group_actions[0].choices)
    for module in icrsumo.app.cli.SUBCOMMANDS:
        functions = [f for _, f in inspect.getmembers(module, inspect.isfunction)
                     if f.__module__ == module.__name__]
        assert {"add", "run"} <= {f.__name__ for f in functions}, module.__name__
        for f in functions:
            assert len(inspect.getsource(f).splitlines()) < 120, f"{module.__name__}.{f.__name__}"
    names = "|".join(re.escape(name) for name in bundled_suites())
    for path in CLI:  # no list of them written out
        assert not re.search(rf"(\b({names})\b,\s*\"?\s*){{4}}", path.read_text(encoding="utf-8")), path
    assert main(["convert-routes", "--help"]) == 0
    shown = " ".join(capsys.readouterr().out.split())
    assert all(name in shown for name in bundled_suites())


def test_notes_name_fields_in_the_readers_words(capsys):
    from icrsumo.app.cli.options import names
    from icrsumo.core.errors import Field, naming_fields, note

    note(f"run it with {Field('replace_agents')} x\x1b[2J")
    with naming_fields(names("evaluate")):
        note(f"run it with {Field('replace_agents')} x", kind="warning")
    note(f"and {Field('rollout_route')}")
    assert capsys.readouterr().err.splitlines() == [
        "icrsumo: note: run it with replace_agents x\\x1b[2J",
        "icrsumo: warning: run it with --replace-agent x",
        "icrsumo: note: and rollout_route"]
