"""The status line a long run prints for whoever watches it: state, MAP, target, dose and alarms
in whole lines at a steady wall interval; none with --quiet."""

from __future__ import annotations

import io
import math
import time

import pytest

from pressor.link import TickInputs
from pressor.runtime.core.closed_loop import TickRecord
from pressor.runtime.core.supervisor_config import FAULT_BITS, State
from pressor.runtime.core.supervisor_io import SupervisorOutput
from pressor.runtime.shell.status import StatusLine
from tests.support.sil_helpers import pressor


def _record(tick: int, map_mmhg: float, command: float, faults: int = 0, state=State.AUTO):
    inputs = TickInputs(tick, tick * 0.1, map_mmhg, 0, 75.0, 1.0, 200.0, 20.0, True, tick, tick)
    out = SupervisorOutput(True, state, faults, 0, None, command, False)
    return TickRecord(inputs, command, math.nan, out, None)


def test_a_line_names_time_state_map_target_dose_per_kg_and_alarms():
    s = StatusLine("pressor run", 0.1, concentration_ug_ml=100.0, weight_kg=70.0)
    # 12 ml/h of 100 ug/ml = 20 ug/min = 0.286 ug/kg/min at 70 kg; tick 3000 = 5 min
    assert s.line(_record(3000, 74.83, 12.0)) == (
        "pressor run  5:00  AUTO  MAP 74.8 mmHg  target 75.0 mmHg  12.0 ml/h = 0.286 µg/kg/min"
        "  alarms: none"
    )
    held = _record(36000, math.nan, 3.0, FAULT_BITS["MAP_NAN"], State.HOLD)
    no_weight = StatusLine("pressor sil", 0.1, concentration_ug_ml=100.0)
    assert no_weight.line(held) == (
        "pressor sil  1:00:00  HOLD  MAP no sample  target 75.0 mmHg  3.0 ml/h = 5.0 µg/min"
        "  alarms: MAP_NAN"
    )


def test_lines_come_whole_at_the_interval_and_not_before():
    out = io.StringIO()
    s = StatusLine("pressor run", 0.1, interval_s=0.05, stream=out, check_every=1)
    s(_record(0, 70.0, 1.0))  # starts the interval
    s(_record(1, 70.0, 1.0))
    assert out.getvalue() == ""
    time.sleep(0.06)
    s(_record(2, 70.0, 1.0))
    assert out.getvalue().count("\n") == 1 and out.getvalue().startswith("pressor run  0:00  AUTO")
    with pytest.raises(ValueError, match="interval_s"):
        StatusLine("pressor run", 0.1, interval_s=0.0)


@pytest.mark.slow  # two 6 s real-time runs; the line's unit tests stay fast
def test_a_real_time_sil_prints_status_lines_unless_quiet(tmp_path):
    # 6 s at a line a second: a loaded machine that starts late and catches up still prints one
    argv = ["sil", "--controller", "pi", "--realtime", "--duration", "6", "--status-every", "1"]
    proc = pressor(*argv, "--rrd", str(tmp_path / "a.rrd"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("pressor sil  0:0")]
    assert len(lines) >= 1 and all(" MAP " in ln and " ml/h = " in ln for ln in lines), lines
    quiet = pressor(*argv, "--quiet", "--rrd", str(tmp_path / "b.rrd"), cwd=tmp_path)
    assert quiet.returncode == 0 and "pressor sil  0:0" not in quiet.stderr
    bad = pressor("run", "--port", "x", "--status-every", "0", cwd=tmp_path)
    assert bad.returncode == 2 and "--status-every" in bad.stderr
