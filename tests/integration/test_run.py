"""``pressor run``: the runtime alone on a serial port, against a device started by hand.

The device and the runtime each open the follower of their own pty, bridged like a null-modem
cable (:func:`tests.support.sil_helpers.bridged_ttys`), so both ends are real ttys.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from pressor.link import Signing
from tests.support.sil_helpers import ROOT, pressor

SEED = 4


def test_run_against_a_hand_started_device_scores_its_faults_without_scenario_events(
    bridged_ports, tmp_path: Path, monkeypatch
):
    device_port, runtime_port = bridged_ports
    # both ends sign by default with the key 'pressor keygen' writes
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    keygen = pressor("keygen", cwd=tmp_path)
    key = tmp_path / "config" / "pressor" / "signing.key"
    assert keygen.returncode == 0 and str(key) in keygen.stdout
    assert key.stat().st_mode & 0o777 == 0o600 and len(key.read_text().strip()) == 64
    assert pressor("keygen", cwd=tmp_path).returncode == 2  # never replaced silently
    fault = "pump-occlusion:5"
    device = subprocess.Popen(
        [sys.executable, "-m", "pressor", "device", "--port", device_port, "--duration", "20"]
        + ["--patient-seed", str(SEED), "--fault", fault],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT), CI="1"),
        stderr=subprocess.DEVNULL,  # the device reads the environment's default key too
    )
    try:
        proc = pressor(
            "run",
            "--port",
            runtime_port,
            "--controller",
            "pi",
            "--fault",
            fault,
            "--summary",
            str(tmp_path / "s.json"),
            cwd=tmp_path,
        )
    finally:
        assert device.wait(timeout=30) == 0
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "s.json").read_text())
    assert (summary["ticks"], summary["patient_seed"], summary["link"]) == (200, SEED, runtime_port)
    assert summary["scenario"] == "paper-tracking" and summary["signed"] is True
    [scored] = summary["faults"]
    assert scored["kind"] == "pump-occlusion" and scored["start_tick"] == 50
    assert scored["within_bound"] is True
    assert summary["metrics"]["disturbances"] is None  # the device's scenario is not known
    assert "pump-occlusion" in proc.stdout and "recording" not in proc.stdout


def test_run_with_an_unopenable_port_exits_2_with_one_line(tmp_path: Path):
    key = Signing.generate().write(tmp_path / "key")  # the key is read first: give a good one
    proc = pressor(
        "run", "--controller", "pi", "--port", str(tmp_path / "no-tty"),
        "--signing-key", str(key), cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 2
    [line] = proc.stderr.strip().splitlines()
    assert line.startswith(f"pressor run: --port {tmp_path / 'no-tty'}: cannot open")


def test_run_signs_by_default_and_without_a_key_says_how_to_make_one(
    bridged_ports, tmp_path: Path, monkeypatch
):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "empty"))
    proc = pressor("run", "--controller", "pi", "--port", bridged_ports[1], cwd=tmp_path)
    assert proc.returncode == 2
    [line] = proc.stderr.strip().splitlines()
    assert "no key at the default" in line and "pressor keygen" in line and "--no-signing" in line
