"""``pressor verify --controller SPEC``: a plugin's nominal step beside the PI and the Smith
predictor, no certificate (and the output says so), exit 0 / 1 by the step, 2 for a spec that
names no plugin; the Smith baseline's step is the same discrete simulation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pressor import cli
from pressor.baselines.smith import SmithController
from pressor.synthesis.verification.discrete_step import discrete_step_response
from pressor.synthesis.verification.smith_baseline import smith_step_response

PLUGINS = str(Path(__file__).resolve().parents[1] / "support" / "controller_plugins.py")
CERTIFICATE = "certificate: not applicable (plugin controller)"


def _verify(capsys, *argv: str) -> tuple[int, str, str]:
    rc = cli.main(["verify", *argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_a_settling_plugin_passes_its_nominal_step_and_says_no_certificate(tmp_path, capsys):
    report = tmp_path / "v.json"
    rc, out, _ = _verify(capsys, "--controller", f"{PLUGINS}:PlainPI", "--json", str(report))
    assert rc == 0, out
    lines = out.splitlines()
    assert lines[0].startswith(f"verifying plugin controller {PLUGINS}:PlainPI (class PlainPI")
    assert lines[1].startswith(CERTIFICATE)
    assert "analysis LMI" not in "".join(lines[2:]) and "delay stability" not in out
    assert [ln.split()[3] for ln in lines if ln.startswith("(c) nominal step ")] == [
        "PLUGIN",
        "PI",
        "SMITH",
    ]
    assert lines[-1] == "verification PASS (nominal step only; no certificate)"
    d = json.loads(report.read_text())
    assert d["passed"] is True and d["certificate"]["applicable"] is False
    assert d["controller"] == {
        "spec": f"{PLUGINS}:PlainPI",
        "class": "PlainPI",
        "kind": "plugin",
        "sample_period_s": 0.1,
        "max_rate_ml_h": 120.0,
    }
    plugin = d["nominal_step"]["plugin"]
    assert plugin["stable"] and plugin["settling_time_s"] < 1500.0
    assert plugin["commands_clamped"] == 0
    assert d["nominal_step"]["smith"]["settling_time_s"] == pytest.approx(277.0, abs=1.0)


@pytest.mark.parametrize(
    ("cls", "needle"),
    [
        ("Raises:at=30", "PLUGIN FAIL: step() raised ZeroDivisionError('plugin bug')"),
        ("FailsAt:at=30,how=nan", "PLUGIN FAIL: the controller returned nan ml/h at t = 2.9 s"),
        ("Runaway", "PLUGIN overshoot"),  # clamped at 120 ml/h every tick: MAP never settles
    ],
)
def test_a_plugin_whose_step_fails_or_never_settles_exits_1(cls, needle, capsys):
    rc, out, _ = _verify(capsys, "--controller", f"tests.support.controller_plugins:{cls}")
    assert rc == 1, out
    assert CERTIFICATE in out and needle in out
    assert out.splitlines()[-1] == "verification FAIL (nominal step only; no certificate)"
    if cls == "Runaway":
        assert "settling n/a" in out and "clamped 15001 ticks" in out


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--controller", "pi"], "takes a plugin"),
        (["--controller", "lpv"], "verified from its artifact"),
        (["--controller", "tests.support.controller_plugins:NoStatus"], "does not satisfy"),
        (["x.npz", "--controller", f"{PLUGINS}:PlainPI"], "give one"),
        (["--controller", f"{PLUGINS}:PlainPI", "--density", "3"], "--density with --controller"),
        (["--controller", f"{PLUGINS}:PlainPI", "--kkt", "qdldl"], "a plugin controller has none"),
        (["--controller", f"{PLUGINS}:PlainPI", "--p-dependence", "affine"], "--p-dependence"),
    ],
)
def test_a_spec_that_names_no_usable_plugin_exits_2_with_one_line(argv, needle, capsys):
    rc, _, err = _verify(capsys, *argv)
    assert rc == 2
    [line] = err.strip().splitlines()
    assert line.startswith("pressor verify: ") and needle in line


def test_the_smith_baseline_step_is_the_generic_discrete_step_of_the_smith_controller():
    ref = smith_step_response(0.55, 150.0, 40.037, 20.0, 300.0, max_rate_ml_h=30.0)
    resp, clamped = discrete_step_response(
        SmithController(0.1, 30.0), 0.55, 150.0, 40.037, 20.0, 300.0
    )
    np.testing.assert_array_equal(resp.map_mmhg, ref.map_mmhg)
    np.testing.assert_array_equal(resp.infusion_ml_h, ref.infusion_ml_h)
    assert clamped == 0  # the Smith predictor clamps itself
