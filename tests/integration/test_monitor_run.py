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

from tests.support.sil_helpers import ROOT, pressor

DURATION_S = 600.0


def _run(ports: tuple[str, str], tmp_path: Path, duration_s: float, *run_args: str) -> dict:
    """``pressor device`` (bedside-monitor) and ``pressor run RUN_ARGS``, signed; the summary."""
    device_port, runtime_port = ports
    assert pressor("keygen", cwd=tmp_path).returncode == 0  # both ends sign with this key
    device = subprocess.Popen(
        [sys.executable, "-m", "pressor", "device", "--port", device_port]
        + ["--scenario", "bedside-monitor", "--duration", str(duration_s), "--patient-seed", "3"],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT), CI="1"),
        stderr=subprocess.DEVNULL,
    )
    try:
        proc = pressor(
            "run",
            *("--port", runtime_port, *run_args, "--summary", str(tmp_path / "s.json")),
            cwd=tmp_path,
            timeout=300,
        )
    finally:
        assert device.wait(timeout=60) == 0
    assert proc.returncode == 0, proc.stderr
    return json.loads((tmp_path / "s.json").read_text())


@pytest.mark.parametrize("controller", ["lpv", "pi"])
def test_a_1hz_quantized_monitor_keeps_the_loop_out_of_failsafe(
    controller: str,
    bridged_ports,
    tmp_path: Path,
    monkeypatch,
):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    # pressor run's default schedule: the online estimator, fed the held values between updates
    s = _run(bridged_ports, tmp_path, DURATION_S, "--controller", controller)
    assert s["ticks"] == round(DURATION_S / 0.1) and s["sensor_noise_mmhg"] == 0.5
    states = s["supervisor"]["ticks_in_state"]
    assert states["FAILSAFE"] == 0 and states["HOLD"] == 0, s["supervisor"]
    assert "MAP_FLATLINE" not in s["supervisor"]["detections"]
    assert "SENSOR_QUALITY" not in s["supervisor"]["detections"]  # HELD is not a quality fault
    assert "STALE_SAMPLE" not in s["supervisor"]["detections"]
    assert abs(s["metrics"]["steady_state_dev_mmhg"]) <= 5.0  # within the clinical band


def test_a_sample_age_limit_below_the_monitors_period_makes_its_held_samples_stale(
    bridged_ports,
    tmp_path: Path,
    monkeypatch,
):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    s = _run(bridged_ports, tmp_path, 30.0, "--controller", "pi", "--sample-age-limit-s", "0.5")
    # each held value is 0.6 s old before the next update: STALE_SAMPLE, HOLD, every second
    assert s["supervisor"]["detections"]["STALE_SAMPLE"] >= 20
    assert s["supervisor"]["ticks_in_state"]["HOLD"] >= 100
