"""docs/C-TARGET.md's minimal program compiles against the committed generated C controller with
every warning an error, runs, and does what the page says: MAP to the target, the rate that holds
it, a sample without a MAP held, the state size the page states."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from pressor.plumbing.native_build import compiler

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "C-TARGET.md"
GENERATED = ROOT / "runtime" / "generated"
WARNINGS = ["-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wshadow", "-Werror"]


def _main_source() -> str:
    """The page's C block (the minimal program)."""
    (block,) = re.findall(r"```c\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S)
    return block


@pytest.fixture(scope="module")
def demo_output(tmp_path_factory) -> str:
    cc = compiler()
    if cc is None:
        pytest.skip("no C compiler (cc, gcc, clang or $CC) on PATH")
    d = tmp_path_factory.mktemp("c_target")
    (d / "main.c").write_text(_main_source())
    build = subprocess.run(
        [cc, "-std=c99", "-O2", *WARNINGS, "-I", str(GENERATED), str(d / "main.c"),
         str(GENERATED / "lpv_map_controller.c"), "-o", str(d / "lpv_demo")],
        capture_output=True, text=True, check=False, timeout=300,
    )  # fmt: skip
    assert build.returncode == 0, build.stderr
    run = subprocess.run([str(d / "lpv_demo")], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    return run.stdout


def test_the_minimal_program_brings_map_to_the_target_at_the_rate_the_page_states(demo_output):
    line = next(x for x in demo_output.splitlines() if x.startswith("after 600 s:"))
    assert line == "after 600 s: MAP 80.0 mmHg, rate 36.36 ml/h = 60.6 ug/min of phenylephrine"
    assert "36.36 ml/h, 60.6 µg/min of phenylephrine" in PAGE.read_text(encoding="utf-8")


def test_a_sample_without_a_map_holds_the_last_rate_and_sets_input_invalid(demo_output):
    assert "no MAP: rate 36.36 ml/h held, input_invalid 1" in demo_output.splitlines()


def test_the_page_states_the_state_size_this_target_has(demo_output):
    size = int(re.search(r"state (\d+) bytes", demo_output).group(1))
    assert f"**{size:,} bytes**" in PAGE.read_text(encoding="utf-8")


def test_the_page_is_linked_from_the_readme():
    assert "(docs/C-TARGET.md)" in (ROOT / "README.md").read_text(encoding="utf-8")
