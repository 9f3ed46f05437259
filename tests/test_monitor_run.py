"""``pressor run`` against ``pressor device`` with a bedside monitor: integer mmHg at 1 Hz with
honest noise (the shipped ``bedside-monitor`` scenario), over real ptys, in lockstep - the device
repeats its value with ``QUALITY_HELD`` on the nine ticks between updates."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.sil_helpers import ROOT, pressor
from tests.test_runtime_run import bridged_ports  # noqa: F401 (a fixture)

DURATION_S = 600.0


@pytest.mark.parametrize("controller", ["lpv", "pi"])
def test_a_1hz_quantized_monitor_keeps_the_loop_out_of_failsafe(
    controller,
    bridged_ports,  # noqa: F811 (the imported fixture)
    tmp_path: Path,
    monkeypatch,
):
    device_port, runtime_port = bridged_ports
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    assert pressor("keygen", cwd=tmp_path).returncode == 0  # both ends sign with this key
    device = subprocess.Popen(
        [sys.executable, "-m", "pressor", "device", "--port", device_port]
        + ["--scenario", "bedside-monitor", "--duration", str(DURATION_S), "--patient-seed", "3"],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT), CI="1"),
        stderr=subprocess.DEVNULL,
    )
    try:
        proc = pressor(
            "run",
            *("--port", runtime_port, "--controller", controller, "--schedule", "oracle"),
            *("--summary", str(tmp_path / "s.json")),
            cwd=tmp_path,
            timeout=300,
        )
    finally:
        assert device.wait(timeout=60) == 0
    assert proc.returncode == 0, proc.stderr
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["ticks"] == round(DURATION_S / 0.1) and s["sensor_noise_mmhg"] == 0.5
    states = s["supervisor"]["ticks_in_state"]
    assert states["FAILSAFE"] == 0 and states["HOLD"] == 0, s["supervisor"]
    assert "MAP_FLATLINE" not in s["supervisor"]["detections"]
    assert "SENSOR_QUALITY" not in s["supervisor"]["detections"]  # HELD is not a quality fault
    assert "STALE_SAMPLE" not in s["supervisor"]["detections"]
    assert abs(s["metrics"]["steady_state_dev_mmhg"]) <= 5.0  # within the clinical band
