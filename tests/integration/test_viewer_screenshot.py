"""scripts/viewer_screenshot.py: a real recording in rerun's real web viewer, in headless Chromium."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pressor.runtime.record.blueprint import SERIES_COLORS

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = Path("/usr/bin/chromium")

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not CHROMIUM.is_file(), reason="needs Chromium (apt-get install chromium)"),
    pytest.mark.skipif(
        importlib.util.find_spec("playwright") is None,
        reason='needs Playwright (pip install -e ".[screenshot]")',
    ),
]


def processes_in(directory: Path) -> list[int]:
    """Pids of the processes whose working directory is ``directory``."""
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and os.readlink(entry / "cwd") == str(directory):
                pids.append(int(entry.name))
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return pids


def test_screenshot_shows_the_measured_map_trace_of_a_real_recording(tmp_path):
    import numpy as np
    from PIL import Image

    subprocess.run(
        ["pressor", "sil", "--duration", "600", "--rrd", "run.rrd"],
        cwd=tmp_path,
        check=True,
        capture_output=True,
    )
    out = tmp_path / "viewer.png"
    subprocess.run(
        [sys.executable, str(ROOT / "scripts/viewer_screenshot.py"), "run.rrd", str(out)],
        cwd=tmp_path,
        check=True,
        capture_output=True,
    )
    assert processes_in(tmp_path) == []  # the rerun launcher's server child is stopped too
    image = Image.open(out).convert("RGB")
    assert image.size == (1600, 1000)
    # the top quarter is the MAP plot: once drawn it holds the MAP lines, the true MAP's purple
    # over the measured blue where they coincide (a viewer still loading shows a uniform page)
    top = np.asarray(image.crop((0, 40, 1600, 250)), dtype=int)
    drawn = 0
    for entity in ("/patient/map_mmhg", "/patient/map_true_mmhg"):
        colour = np.array(SERIES_COLORS[entity])
        drawn += int((np.abs(top - colour).max(axis=2) <= 12).sum())
    assert drawn > 300
