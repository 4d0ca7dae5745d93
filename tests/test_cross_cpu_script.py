"""tools/cross_cpu.sh (the same evaluation on another CPU, docs/exact.md): its commands parse,
an unknown one is one line with exit status 2, and ``copy`` takes exactly what a run on another
machine needs from an evaluation folder (its configuration, scenarios and instructions, not its
results)."""

import subprocess
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "cross_cpu.sh"


def test_the_script_parses_and_refuses_an_unknown_command():
    assert subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True, timeout=30).returncode == 0
    r = subprocess.run(["bash", str(SCRIPT), "nope"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "unknown command nope" in r.stderr


def test_copy_takes_the_configuration_scenarios_and_instructions(tmp_path):
    out = tmp_path / "out"
    for d in ("scenarios/r1", "instructions"):
        (out / d).mkdir(parents=True)
    (out / "config.json").write_text("{}")
    (out / "scenarios/r1/manifest.json").write_text("{}")
    (out / "instructions/r1.json").write_text("[]")
    (out / "results.sqlite").write_bytes(b"not copied")
    dst = tmp_path / "pack" / "runs" / "tiny"
    r = subprocess.run(["bash", str(SCRIPT), "copy", str(out), str(dst)], capture_output=True, text=True,
                       timeout=30)
    assert r.returncode == 0, r.stderr
    got = sorted(str(p.relative_to(dst)) for p in dst.rglob("*") if p.is_file())
    assert got == ["config.json", "instructions/r1.json", "scenarios/r1/manifest.json"]
