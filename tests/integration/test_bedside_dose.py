"""Dose limits on elapsed time, with a taper: a real ``pressor run`` (drug library: phenylephrine,
hard 200 ug/min = 120 ml/h, soft 100 ug/min = 60 ml/h, 6000 ug = 60 ml per hour) against a probing
device whose patient's MAP stays low, at 1 Hz so that the hour fits in the test."""

from __future__ import annotations

import pytest

from pressor.link import MODE_AUTO
from tests.support.probe_device import probe_run


def test_the_first_commands_respect_the_soft_limit_unless_confirmed(tmp_path):
    with probe_run(tmp_path, n_ticks=60) as r:
        r.probe.run(range(60), map_mmhg=60.0, target_mmhg=80.0)  # 20 mmHg short
        r.probe.finish(60)
        code = r.wait()
    assert code == 0, r.err
    rates = [r.probe.commands[k].rate_ml_h for k in range(60)]
    assert max(rates) == pytest.approx(60.0)  # the soft maximum, 100 ug/min
    assert "DOSE_SOFT_LIMIT" in r.err and "soft maximum 60 ml/h (not confirmed above)" in r.err
    assert r.summary["dose"]["max_command_ug_min"] == pytest.approx(100.0)


def test_the_hourly_limit_tapers_is_a_visible_alarm_and_names_the_shortfall(tmp_path):
    """MAP stuck 30 mmHg below target: the controller asks the pump maximum; confirmed above the
    soft maximum, 120 ml/h uses the 60 ml of the hour in 30 min. The command tapers instead of
    falling to 0, the state stays AUTO with the limit raised, and 10 min into the cut an alarm
    names the limit and the shortfall."""
    n = 45 * 60  # 45 min at 1 Hz
    args = ("--rate", "1", "--confirm-above-soft-limit")
    with probe_run(tmp_path, *args, n_ticks=n, period_s=1.0) as r:
        r.probe.run(range(n), map_mmhg=50.0, target_mmhg=80.0)
        r.probe.finish(n)
        code = r.wait(timeout_s=120.0)
    assert code == 0, r.err
    cmds = [r.probe.commands[k] for k in range(n)]
    rates = [c.rate_ml_h for c in cmds]
    assert max(rates) == pytest.approx(120.0)
    assert all(c.mode == MODE_AUTO for c in cmds[5:])  # control went on, the limit is a cut
    drops = [a - b for a, b in zip(rates, rates[1:], strict=False)]
    assert max(drops) < 1.0  # no cliff: at most 1 ml/h less from one second to the next
    assert min(rates[30 * 60 :]) > 5.0  # never 0 while the hour has room
    assert sum(rates) / 3600.0 <= 60.0 * (1 + 1e-6)  # the hour's maximum, 60 ml, holds
    assert "DOSE_HOUR_LIMIT" in r.err and "hourly maximum 60 ml" in r.err
    assert "DOSE_SHORTFALL" in r.err and "30.0 mmHg below the target" in r.err
    det = r.summary["supervisor"]["detections"]
    assert det["DOSE_HOUR_LIMIT"] >= 1 and det["DOSE_SHORTFALL"] == 1
