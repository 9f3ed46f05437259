"""The runtime package never loads the solver stack or the simulated patient (docs/ARCHITECTURE.md)."""

from __future__ import annotations

import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: what no runtime module may load: the solver stack and the simulator
FORBIDDEN = ("pressor.synthesis", "cvxpy", "clarabel", "pressor.hil_sim")


def runtime_modules() -> list[str]:
    import pressor.runtime as runtime

    names = ["pressor.runtime"]
    for info in pkgutil.walk_packages(runtime.__path__, prefix="pressor.runtime."):
        names.append(info.name)
    return sorted(names)


def test_runtime_module_list_covers_loop_cli_supervisor_and_recorder():
    names = runtime_modules()
    for expected in (
        "pressor.runtime.shell.loop",
        "pressor.runtime.cli",
        "pressor.runtime.core.supervisor",
        "pressor.runtime.record.recorder",
    ):
        assert expected in names


@pytest.mark.parametrize("module", runtime_modules())
def test_importing_runtime_module_loads_no_solver_and_no_simulator(module):
    code = (
        "import importlib, sys\n"
        f"importlib.import_module({module!r})\n"
        f"bad = sorted(m for m in sys.modules if any(m == f or m.startswith(f + '.') for f in {FORBIDDEN!r}))\n"
        "print(','.join(bad))\n"
    )
    env = dict(os.environ, CI="1")
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "", f"{module} imported {proc.stdout.strip()}"
