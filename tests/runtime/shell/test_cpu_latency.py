"""CPU wake-up latency request (pressor.runtime.shell.cpu_latency): the request, its option, its report."""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import pytest

from pressor.plumbing.usage import UsageError, UsageParser
from pressor.runtime.inputs.config import add_run_options
from pressor.runtime.shell.cpu_latency import QOS_DEVICE, CpuLatencyRequest
from tests.support.sil_helpers import pressor


def test_request_writes_native_int32_and_releases_on_exit(tmp_path):
    dev = tmp_path / "qos"
    dev.write_bytes(b"")
    with CpuLatencyRequest(7, device=str(dev)) as req:
        assert req.held
        assert "held at 7 us" in req.status
        assert dev.read_bytes() == struct.pack("=i", 7)
        fd = req._fd
        assert fd is not None
        os.fstat(fd)  # open while the block runs
    assert not req.held
    with pytest.raises(OSError):
        os.fstat(fd)  # closing the descriptor is what withdraws the request


def test_unavailable_device_is_reported_not_raised(tmp_path):
    with CpuLatencyRequest(0, device=str(tmp_path / "missing" / "qos")) as req:
        assert not req.held
        assert req.status.startswith("not held: cannot open")


def test_no_request_touches_nothing(tmp_path):
    dev = tmp_path / "qos"
    with CpuLatencyRequest(None, device=str(dev)) as req:
        assert not req.held
    assert not dev.exists()


@pytest.mark.parametrize("bad", [-1, 1_000_001])
def test_latency_outside_range_is_refused(bad):
    with pytest.raises(ValueError, match=r"must be an integer in \[0, 1000000\] µs"):
        CpuLatencyRequest(bad)


@pytest.mark.parametrize(
    ("option", "latency_us"),
    [([], None), (["--cpu-latency", "hold"], 0), (["--cpu-latency", "50"], 50)],
)
def test_cpu_latency_request_is_opt_in(option, latency_us):
    p = UsageParser(prog="pressor run")
    add_run_options(p)
    assert p.parse_args(option).cpu_latency == latency_us


@pytest.mark.parametrize("option", [["--cpu-latency", "-5"], ["--cpu-latency", "fast"]])
def test_bad_cpu_latency_option_is_a_usage_error_naming_it(option):
    p = UsageParser(prog="pressor run")
    add_run_options(p)
    with pytest.raises(UsageError, match="--cpu-latency"):
        p.parse_args(option)


def test_sil_timing_reports_the_wake_latency_request_and_placement(tmp_path: Path):
    proc = pressor(
        "sil",
        "--controller",
        "pi",
        "--duration",
        "20",
        "--cpu-latency",
        "hold",
        "--rrd",
        str(tmp_path / "r.rrd"),
        "--timing",
        str(tmp_path / "t.json"),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    host = json.loads((tmp_path / "t.json").read_text())["host"]
    writable = os.access(QOS_DEVICE, os.W_OK)
    assert host["cpu_latency"].startswith("held at 0 us" if writable else "not held")
    assert f"CPU wake-up latency request {host['cpu_latency']}" in proc.stdout
    if len(os.sched_getaffinity(0)) >= 2:
        assert host["cpus"][0] != host["cpus"][1]
