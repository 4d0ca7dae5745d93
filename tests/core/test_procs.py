"""icrsumo's own process pools from a plain script: the children never run the parent's script
again (a script without an ``if __name__ == "__main__":`` guard works, as docs/api.md's example
is written)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.sumo


def test_a_script_without_a_main_guard_evaluates(tmp_path):
    # two workers: the conversion and generation pools spawn children, which used to import this
    # script again as __mp_main__, start a second run in the same folder and break the pool
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent("""\
        import icrsumo
        run = icrsumo.evaluate(suite="tiny", agents=["route-oracle"], families=["misleading"], k=1,
                               routes=["tiny_003"], out="icr_out", workers=2)
        print("done", run.done, run.crashed)
        """), encoding="utf-8")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.splitlines() == ["done 2 0"]
    assert (tmp_path / "icr_out" / "summary.json").is_file()


def test_spawned_children_do_not_see_the_script(tmp_path):
    from icrsumo.core.procs import spawn_context

    script = tmp_path / "probe.py"
    script.write_text(textwrap.dedent("""\
        import sys
        from icrsumo.core.procs import spawn_context
        print("script ran", flush=True)
        with spawn_context().Pool(1) as pool:
            print(pool.apply(sorted, ([3, 1, 2],)))
        """), encoding="utf-8")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.splitlines() == ["script ran", "[1, 2, 3]"]
    assert spawn_context().get_start_method() == "spawn"
