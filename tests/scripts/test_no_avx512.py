"""scripts/no_avx512/run.sh: a command run through it sees a CPU without AVX-512, its children
too, and real crashes still crash (docs/PLATFORM-NOTES.md)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

RUN = Path(__file__).resolve().parents[2] / "scripts" / "no_avx512" / "run.sh"


def _cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


pytestmark = pytest.mark.skipif(
    not {"avx512f", "cpuid_fault"} <= _cpu_flags() or shutil.which("cc") is None,
    reason="needs an x86-64 Linux CPU with AVX-512 and CPUID faulting, and a C compiler",
)

FEATURES = (
    "from numpy._core._multiarray_umath import __cpu_features__ as f; "
    "print(f['AVX512F'], f['AVX2'], f['FMA3'])"
)


#: the environment without the script's own variables, so the check also holds when the suite
#: itself runs under the script (the CPU seen by a child is then the real one again)
NATIVE_ENV = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "GLIBC_TUNABLES")}


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", str(RUN), sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env=NATIVE_ENV,
    )


def test_numpy_sees_avx2_and_fma_but_no_avx512_through_the_script() -> None:
    assert subprocess.run(
        [sys.executable, "-c", FEATURES], capture_output=True, text=True, check=True, env=NATIVE_ENV
    ).stdout.split() == ["True", "True", "True"]
    out = _run(FEATURES)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True", "True"]


def test_a_child_process_inherits_the_masked_cpu() -> None:
    code = f"import subprocess, sys; subprocess.run([sys.executable, '-c', {FEATURES!r}])"
    out = _run(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True", "True"]


def test_a_real_segmentation_fault_still_reaches_the_programs_handler_and_kills() -> None:
    out = _run("import faulthandler, ctypes; faulthandler.enable(); ctypes.string_at(0)")
    assert out.returncode == -signal.SIGSEGV
    assert "Fatal Python error: Segmentation fault" in out.stderr
