"""`pressor sil` end to end: a real device process over a pty, compared with pressor.hil_sim.episode.

The test may import sim (the runtime may not): it is the independent reference.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.support.sil_helpers import assert_recording_equals_simulation, pressor, rrd_columns

DURATION_S = 300
SEED = 3


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("sil")
    runs = []
    for i in range(2):
        rrd, summary = d / f"r{i}.rrd", d / f"s{i}.json"
        proc = pressor(
            "sil",
            "--controller",
            "pi",
            "--scenario",
            "paper-tracking",
            "--patient-seed",
            str(SEED),
            "--duration",
            str(DURATION_S),
            "--rrd",
            str(rrd),
            "--summary",
            str(summary),
            "--tlog",
            str(d / f"t{i}.tlog"),
            cwd=d,
        )
        runs.append((proc, rrd, summary))
    return runs


def test_sil_exits_0_and_prints_summary_and_replay_command(two_runs):
    proc, rrd, _ = two_runs[0]
    assert proc.returncode == 0, proc.stderr
    assert "time within ±5 mmHg of the target" in proc.stdout
    from pressor.runtime.summary import replay_command

    assert f"replay:    {replay_command(rrd)}" in proc.stdout  # the child has this environment


def test_sil_summary_reads_for_a_person_start_map_target_drug_dose_and_no_raw_names(two_runs):
    proc, _, summary = two_runs[0]
    out = proc.stdout
    s = json.loads(summary.read_text())
    assert "time_in_band_pct" in s["metrics"]  # the JSON keeps the names programs read
    assert "patient: start MAP " in out and " mmHg, target " in out
    assert "drug: phenylephrine 100 µg/ml; patient weight not known" in out
    line = next(x for x in out.splitlines() if x.startswith("infusion: "))
    assert "ml/h = " in line and "µg/kg/min" in line
    assert "time_in_band_pct" not in out and "mdpe_pct" not in out
    assert "{'" not in out and "null" not in out
    assert "cpu wake-up latency" not in out  # nothing asked for, nothing said


def test_sil_trajectory_equals_in_process_simulator(two_runs):
    from pressor.baselines.pi import PIController
    from pressor.hil_sim.episode import simulate
    from pressor.hil_sim.world import World

    _, rrd, _ = two_runs[0]
    ref = simulate(World("paper-tracking", SEED, 0.1), PIController(0.1), float(DURATION_S))
    n = ref.t_s.size
    cols = rrd_columns(rrd)
    for entity in ("/patient/map_mmhg", "/controller/target_mmhg", "/pump/command_ml_h"):
        assert sorted(cols[entity]) == list(range(n)), entity  # every tick recorded
    sil_map = np.array([cols["/patient/map_mmhg"][k] for k in range(n)])
    sil_target = np.array([cols["/controller/target_mmhg"][k] for k in range(n)])
    sil_cmd = np.array([cols["/pump/command_ml_h"][k] for k in range(n)], dtype=np.float32)
    np.testing.assert_array_equal(sil_map, ref.map_mmhg)
    np.testing.assert_array_equal(sil_target, ref.target_mmhg)
    np.testing.assert_array_equal(sil_cmd.astype(np.float64), ref.command_ml_h)
    assert np.ptp(sil_cmd) > 10.0  # the loop actually did something


def test_two_sil_runs_give_identical_summaries(two_runs):
    (_, _, s0), (_, _, s1) = two_runs
    a, b = json.loads(s0.read_text()), json.loads(s1.read_text())
    assert a == b
    assert a["ticks"] == DURATION_S * 10
    assert a["signed"] is True
    assert a["metrics"]["commands_out_of_range"] == 0
    assert a["supervisor"]["ticks_in_state"]["AUTO"] == DURATION_S * 10


def test_sil_bad_input_exits_2_with_one_line_naming_the_option(tmp_path):
    proc = pressor("sil", "--controller", "pi", "--duration", "-5", cwd=tmp_path)
    assert proc.returncode == 2
    assert "--duration" in proc.stderr and "(0," in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    proc = pressor("sil", "--controller", "nope.py", cwd=tmp_path)
    assert proc.returncode == 2 and "nope.py" in proc.stderr


def test_sil_unknown_scenario_exits_2_and_writes_no_recording(tmp_path):
    proc = pressor(
        "sil", "--controller", "pi", "--scenario", "no-such", "--rrd", "x.rrd", cwd=tmp_path
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "no-such" in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_faults_lists_each_detected_kind_with_its_bound(tmp_path):
    proc = pressor("faults", cwd=tmp_path)
    assert proc.returncode == 0
    for kind in ("MAP_NAN", "MAP_RANGE", "MAP_SPIKE", "MAP_FLATLINE", "STALE_SAMPLE", "LINK_LOSS"):
        assert kind in proc.stdout
    assert "sample older than 3.0 s" in proc.stdout  # the default sample age limit
    assert "23 at noise 1 mmHg, quantum 1 mmHg" in proc.stdout  # the stuck rule's count


@pytest.mark.slow  # test_sil_trajectory_equals_in_process_simulator is its fast sibling (the PI)
def test_sil_with_shipped_lpv_over_30_min_equals_in_process_simulator(tmp_path):
    """The issue's done-when run: lpv, paper-tracking, patient seed 3, 1800 s, over a pty."""
    from pressor.hil_sim.episode import simulate
    from pressor.hil_sim.world import World
    from pressor.runtime.inputs.controller_loader import load_controller

    rrd, summary = tmp_path / "lpv.rrd", tmp_path / "lpv.json"
    proc = pressor(
        "sil",
        *("--controller", "lpv", "--schedule", "oracle", "--scenario", "paper-tracking"),
        *("--patient-seed", str(SEED), "--duration", "1800"),
        *("--rrd", str(rrd), "--summary", str(summary)),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(summary.read_text())["controller"].endswith("lpv")
    ref = simulate(World("paper-tracking", SEED, 0.1), load_controller("lpv"), 1800.0)
    sil_cmd = assert_recording_equals_simulation(rrd, ref)
    assert sil_cmd.max() > 10.0


def test_sil_without_disturbance_reports_whole_run_step_metrics_and_no_events(two_runs):
    _, _, s0 = two_runs[0]
    m = json.loads(s0.read_text())["metrics"]
    assert m["disturbances"] == []  # paper-tracking has no hemorrhage or bolus
    for old in ("overshoot_pct", "rise_time_s", "settling_time_s", "iae_mmhg_s"):
        assert m[f"step_{old}"] == m[old]


def test_sil_reads_the_scenario_files_disturbances_into_the_summary(tmp_path):
    scenario = tmp_path / "dip.toml"
    scenario.write_text(
        'name = "dip"\nduration_s = 300.0\n[patient]\nmode = "nonlinear"\n'
        "[target]\nstep_mmhg = 20.0\n"
        '[[disturbances]]\nkind = "sinusoid"\nstart_s = 0.0\namplitude_mmhg = 1.0\n'
        "period_s = 600.0\n"
        '[[disturbances]]\nkind = "hemorrhage"\nstart_s = 150.0\nramp_s = 30.0\n'
        "depth_mmhg = 10.0\n"
    )
    summary = tmp_path / "s.json"
    proc = pressor(
        "sil",
        *("--controller", "pi", "--scenario", str(scenario), "--duration", "300"),
        *("--rrd", str(tmp_path / "r.rrd"), "--summary", str(summary)),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    m = json.loads(summary.read_text())["metrics"]
    (hem,) = m["disturbances"]  # the sinusoid is background, not an event
    assert (hem["kind"], hem["start_s"]) == ("hemorrhage", 150.0)
    assert hem["end_s"] == pytest.approx(300.0, abs=1e-3)
    assert hem["peak_deviation_mmhg"] < 0.0
    assert 0.0 < m["step_iae_mmhg_s"] < m["iae_mmhg_s"]
    assert "hemorrhage at 150 s: peak deviation" in proc.stdout
