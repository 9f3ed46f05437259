"""Cohort trials on a real Dask cluster on localhost give the local run's bytes (pressor.plumbing.parallel)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from pressor.hil_sim.cli import main
from pressor.plumbing.parallel import BackendError, run_ordered

distributed = pytest.importorskip("distributed")

FILES = ("patients.json", "patients.csv", "summary.json")


@pytest.fixture(scope="module")
def cluster():
    """Two single-threaded worker processes and a scheduler on localhost (dashboard on a free port)."""
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as c:
        yield c


@pytest.fixture()
def scenario(short_tracking_scenario: Path) -> Path:
    return short_tracking_scenario


def _trial(out: Path, scenario: Path, *extra: str) -> Path:
    argv = ["--controller", "pi", "--schedule", "oracle", "--patients", "6", "--seed", "3"]
    argv += ["--scenario", str(scenario)]
    assert main("trial", [*argv, *extra, "--out", str(out)]) == 0
    return out


def test_trial_on_a_dask_cluster_writes_the_local_runs_bytes(tmp_path, scenario, cluster):
    local = _trial(tmp_path / "local", scenario)
    remote = _trial(tmp_path / "dask", scenario, "--scheduler", cluster.scheduler_address)
    for name in FILES:
        assert (remote / name).read_bytes() == (local / name).read_bytes(), name


def test_a_plugin_patient_model_on_a_dask_cluster_writes_the_in_process_bytes(
    tmp_path, scenario, cluster
):
    plugin = (
        "--patient-model",
        "tests.support.patient_plugin:FirstOrderPatient",
    )  # imported by workers
    local = _trial(tmp_path / "local", scenario, *plugin)
    remote = _trial(tmp_path / "dask", scenario, *plugin, "--scheduler", cluster.scheduler_address)
    for name in FILES:
        assert (remote / name).read_bytes() == (local / name).read_bytes(), name
    assert (
        b'"patient_model": "tests.support.patient_plugin:FirstOrderPatient"'
        in (local / "summary.json").read_bytes()
    )


def _square(x: int) -> int:
    return x * x


def test_results_come_back_in_task_order_with_progress_to_the_total(cluster):
    seen: list[tuple[int, int]] = []
    out = run_ordered(
        _square,
        list(range(12)),
        scheduler=cluster.scheduler_address,
        progress=lambda d, n: seen.append((d, n)),
    )
    assert out == [x * x for x in range(12)]
    assert [d for d, _ in seen] == list(range(1, 13)) and {n for _, n in seen} == {12}


def test_a_worker_killed_mid_trial_costs_only_a_retry_not_the_records(tmp_path, scenario):
    local = _trial(tmp_path / "local", scenario)
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as c,
        distributed.Client(c) as client,
    ):
        pids = list(client.run(os.getpid).values())
        killed: list[int] = []

        def kill_one_worker(done: int, total: int) -> None:
            if done == 1 and not killed:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])

        from pressor.contracts.drug import DEFAULT_BINDING
        from pressor.hil_sim.scenarios.scenario import load_scenario
        from pressor.hil_sim.trials.outputs import write_outputs
        from pressor.hil_sim.trials.trial import run_cohort

        sc = load_scenario(str(scenario))
        records, summary, _ = run_cohort(  # as pressor trial runs it: pi on the paper's drug
            sc,
            "pi",
            3,
            6,
            progress=kill_one_worker,
            scheduler=c.scheduler_address,
            drug=DEFAULT_BINDING,
        )
        write_outputs(tmp_path / "killed", records, summary)
    assert killed
    for name in FILES:
        assert (tmp_path / "killed" / name).read_bytes() == (local / name).read_bytes(), name


def test_an_unreachable_scheduler_is_one_line_naming_the_address_and_exit_2(
    tmp_path, scenario, capsys, monkeypatch
):
    monkeypatch.setattr(
        "pressor.plumbing.parallel.DASK_CONNECT_TIMEOUT_S", 1.0
    )  # nothing listens on :9
    argv = ["--controller", "pi", "--patients", "2", "--scenario", str(scenario)]
    rc = main("trial", [*argv, "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path / "o")])
    # the PI's cohort is warned of as it starts (not the cautious start); then one line
    warned, line = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert warned.startswith("pressor trial: warning: --controller pi")
    assert "tcp://127.0.0.1:9" in line and "dask scheduler" in line
    with pytest.raises(BackendError):
        run_ordered(_square, [1], scheduler="tcp://127.0.0.1:9")
