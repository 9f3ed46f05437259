"""A run that nothing sizes its first doses for the most sensitive patient says so as it starts:
``pressor sil`` on stderr, in its summary and in its recording, ``pressor trial`` on stderr,
naming the controller, the schedule and the designs that start safe; the default configuration
says nothing (runtime/inputs/defaults.py, ``caution_warning``)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.support.scripted_run import recorded_events
from tests.support.sil_helpers import pressor

WARNED = "warning: --controller {spec} on --schedule {schedule} does not start cautiously"


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


def test_a_sil_run_of_the_pi_is_warned_once_on_stderr_in_its_summary_and_recording(tmp_path: Path):
    summary = tmp_path / "s.json"
    out = pressor(
        "sil", "--controller", "pi", "--duration", "5", "--summary", str(summary),
        "--rrd", str(tmp_path / "r.rrd"), cwd=tmp_path,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    [line] = _lines(out.stderr)
    assert line.startswith("pressor sil: " + WARNED.format(spec="pi", schedule="estimated")), line
    assert "lpv:cautious" in line
    said = json.loads(summary.read_text())["caution_warning"]
    assert line.endswith(said)
    assert (0, said) in recorded_events(tmp_path / "r.rrd")  # the clinician's timeline says it


def test_the_default_sil_run_starts_cautiously_and_warns_of_nothing(tmp_path: Path):
    summary = tmp_path / "s.json"
    out = pressor(
        "sil",
        "--duration",
        "5",
        "--summary",
        str(summary),
        "--rrd",
        str(tmp_path / "r.rrd"),
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    assert "warning" not in out.stderr
    assert "caution_warning" not in json.loads(summary.read_text())
    assert not any("cautiously" in text for _, text in recorded_events(tmp_path / "r.rrd"))


def test_a_trial_of_the_fixed_box_design_is_warned_before_it_runs(tmp_path: Path):
    out = pressor(
        "trial", "--controller", "lpv,lpv:cautious", "--patients", "1", "--duration", "30",
        "--out", str(tmp_path / "t"), cwd=tmp_path,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    [line] = [ln for ln in _lines(out.stderr) if "warning" in ln]  # lpv's, not lpv:cautious's
    assert line.startswith("pressor trial: " + WARNED.format(spec="lpv", schedule="estimated"))
