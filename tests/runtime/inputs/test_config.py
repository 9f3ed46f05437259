"""The runtime's typed run configuration (pressor.runtime.inputs.config): checked once, at the command
line."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from pressor.plumbing.usage import UsageError, UsageParser
from pressor.runtime.inputs.config import RunConfig, add_run_options, run_config


def _config(*argv: str, ticks: int = 0) -> RunConfig:
    p = UsageParser(prog="pressor run")
    add_run_options(p)
    return run_config(p.parse_args(list(argv)), ticks=ticks)


def test_options_become_a_frozen_config_with_defaults_and_units(tmp_path: Path):
    cfg = _config(
        "--controller", "pi", "--fault", "pump-occlusion:300", "--rrd", str(tmp_path / "r.rrd")
    )
    assert (cfg.controller, cfg.rate_hz, cfg.period_s, cfg.mode) == ("pi", 10.0, 0.1, "lockstep")
    assert cfg.faults == ("pump-occlusion:300",)
    assert [(f.kind, f.start_s) for f in cfg.fault_specs] == [("pump-occlusion", 300.0)]
    assert cfg.cpu_latency_us is None and cfg.stall_timeout_s == 10.0 and cfg.ticks == 0
    assert cfg.rrd == tmp_path / "r.rrd" and cfg.summary is None
    assert cfg.schedule == "estimated"  # the default the command chose
    assert cfg.sample_age_limit_s == 3.0  # a held MAP sample is used for 3 s, then stale
    assert _config("--controller", "pi", "--sample-age-limit-s", "1.5").sample_age_limit_s == 1.5
    assert _config("--controller", "pi", "--schedule", "nominal").schedule == "nominal"
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.rate_hz = 20.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("argv", "ticks", "needles"),
    [
        (["--rate", "0"], 0, ["--rate", "= 0.0:", "(0, 1000]"]),
        (["--rate", "2000"], 0, ["--rate", "= 2000.0:", "(0, 1000]"]),
        (["--stall-timeout", "nan"], 0, ["--stall-timeout", "= nan:", "(0, 3600]"]),
        (["--controller", "pi"], -1, ["--ticks -1", ">= 0"]),
        (["--controller", "pi", "--rrd", "run.txt"], 0, ["--rrd run.txt", ".rrd"]),
        (
            ["--controller", "pi", "--summary", "/nonexistent/s.json"],
            0,
            ["--summary", "/nonexistent"],
        ),
        (["--controller", "smith:1"], 0, ["--controller smith:1", "[5, 600] s"]),
        (["--controller", "pi", "--fault", "no-such-fault"], 0, ["no-such-fault"]),
        (
            ["--controller", "pi", "--sample-age-limit-s", "0.05"],
            0,
            ["--sample-age-limit-s 0.05", "[1/--rate = 0.1, 60] s"],
        ),
        (["--sample-age-limit-s", "61"], 0, ["--sample-age-limit-s", "= 61.0:", "(0, 60]"]),
    ],
)
def test_a_bad_value_is_one_usage_error_naming_option_value_and_range(argv, ticks, needles):
    with pytest.raises(UsageError) as info:
        _config(*argv, ticks=ticks)
    message = str(info.value)
    assert "\n" not in message
    for needle in needles:
        assert needle in message
