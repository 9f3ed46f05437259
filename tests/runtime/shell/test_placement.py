"""CPU placement of the lockstep ends (pressor.runtime.shell.placement), used by pressor sil and pressor
device."""

from __future__ import annotations

import argparse
import os
import threading

import pytest

from pressor.hil_sim.devices.device import main as device_main
from pressor.plumbing.usage import UsageError
from pressor.runtime.shell.placement import Pinned, lockstep_cpus, parse_cpu
from pressor.sil import sil_parser


def test_sil_cpu_option_takes_one_or_two_allowed_cpus():
    allowed = sorted(os.sched_getaffinity(0))
    args = sil_parser().parse_args(["--cpu", f"{allowed[0]},{allowed[-1]}"])
    assert args.cpu == (allowed[0], allowed[-1])
    assert sil_parser().parse_args(["--cpu", str(allowed[0])]).cpu == (allowed[0], allowed[0])
    with pytest.raises(UsageError, match="--cpu"):
        sil_parser().parse_args(["--cpu", f"{allowed[0]},{max(allowed) + 1}"])


def test_auto_puts_the_two_lockstep_ends_on_different_cpus():
    allowed = os.sched_getaffinity(0)
    cpus = lockstep_cpus("auto", realtime=False)
    if len(allowed) < 2:
        assert cpus is None
    else:
        assert cpus is not None and cpus[0] != cpus[1] and set(cpus) <= allowed
    assert lockstep_cpus("auto", realtime=True) is None
    assert lockstep_cpus("none", realtime=False) is None
    assert lockstep_cpus((0, 1), realtime=False) == (0, 1)


def test_device_cpu_must_be_an_allowed_cpu():
    allowed = sorted(os.sched_getaffinity(0))
    assert parse_cpu(str(allowed[-1])) == allowed[-1]
    for bad in (str(max(allowed) + 1), "x"):
        with pytest.raises(
            argparse.ArgumentTypeError, match=rf"--cpu '{bad}': allowed one of the CPUs"
        ):
            parse_cpu(bad)


def test_device_with_a_cpu_it_may_not_use_exits_2_naming_it(capsys):
    bad = max(os.sched_getaffinity(0)) + 1
    rc = device_main("device", ["--port", "loop://", "--cpu", str(bad)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("pressor device: argument --cpu") and str(bad) in err
    assert len(err.splitlines()) == 1


def test_pinned_runs_the_thread_on_one_cpu_and_restores_its_set():
    seen: dict[str, set[int]] = {}

    def body() -> None:
        before = os.sched_getaffinity(0)
        cpu = max(before)
        with Pinned(cpu):
            seen["inside"] = os.sched_getaffinity(0)
        seen["after"] = os.sched_getaffinity(0)
        seen["before"] = before

    t = threading.Thread(target=body)  # a thread of its own: the test runner's stays untouched
    t.start()
    t.join()
    assert seen["inside"] == {max(seen["before"])}
    assert seen["after"] == seen["before"]
    with Pinned(None):
        assert os.sched_getaffinity(0) == seen["before"]
