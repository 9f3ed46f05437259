"""Plugin controllers in real ``pressor sil`` processes (device process, pty, signed link): a
runaway one is clamped and alarmed, a raising one ends the run with one line and exit 1 (the
researcher sees the bug; ``pressor run`` holds instead: test_controller_faults_run.py)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.support.sil_helpers import pressor, rrd_columns

PLUGINS = str(Path(__file__).resolve().parents[1] / "support" / "controller_plugins.py")


def test_sil_clamps_and_alarms_a_runaway_plugin(tmp_path):
    summary = tmp_path / "s.json"
    proc = pressor(
        "sil",
        "--controller",
        f"{PLUGINS}:Runaway",
        "--duration",
        "20",
        "--rrd",
        "r.rrd",
        "--summary",
        str(summary),
        cwd=tmp_path,
        timeout=60,
    )
    assert proc.returncode in (0, 1), proc.stderr  # 1: a metric check failed, not the run
    doc = json.loads(summary.read_text())
    assert doc["supervisor"]["detections"].get("COMMAND_CLAMPED") == 1
    assert doc["metrics"]["max_rate_ml_h"] <= 120.0
    assert doc["commands_out_of_range"] == 0


def test_sil_with_a_raising_plugin_is_one_line_and_exit_1(tmp_path):
    proc = pressor(
        "sil",
        "--controller",
        f"{PLUGINS}:Raises:at=30",
        "--duration",
        "20",
        "--rrd",
        "r.rrd",
        cwd=tmp_path,
        timeout=60,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    # a plugin on the estimate is warned of at its start (not the cautious start); then one line
    warned, line = proc.stderr.strip().splitlines()
    assert warned.startswith("pressor sil: warning: --controller") and "cautiously" in warned
    assert "ZeroDivisionError('plugin bug')" in line, proc.stderr
    assert "'Raises'" in line and "tick" in line
    # the record of a failed run is kept, up to the tick the controller raised at
    assert sorted(rrd_columns(tmp_path / "r.rrd")["/pump/command_ml_h"]) == list(range(29))
