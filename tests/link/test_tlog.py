"""A ``.tlog`` decodes with pymavlink's stock ``mavlogdump.py`` by the one command in the README."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from pressor.link import (
    STATE_RUNNING,
    DeviceSession,
    Hello,
    ManualClock,
    RuntimeSession,
    Signing,
    TlogWriter,
)
from tests.support.link_doubles import drain, loop_pair, tick_inputs

ROOT = Path(__file__).resolve().parents[2]


def _readme_command() -> list[str]:
    text = (ROOT / "README.md").read_text()
    (line,) = re.findall(r"^ {4}(MAVLINK20=.*mavlogdump\.py.*run\.tlog)$", text, re.M)
    return shlex.split(line)


def test_a_signed_tlog_decodes_with_stock_mavlogdump_by_the_readme_command(tmp_path):
    exe = shutil.which("mavlogdump.py")
    if exe is None:
        pytest.skip("pymavlink's mavlogdump.py is not on PATH")
    import pymavlink

    # the module mavlogdump generates from the XML on first use: start from the current XML
    (Path(pymavlink.__file__).parent / "dialects" / "v20" / "pressor.py").unlink(missing_ok=True)
    a, b = loop_pair()
    key = Signing.generate(seed=3)
    tlog = TlogWriter(tmp_path / "run.tlog")
    dev = DeviceSession(a, signing=key, clock=ManualClock())
    rt = RuntimeSession(b, signing=key, tlog=tlog)
    dev.send_hello(
        Hello("paper-tracking", 7, 0.1, 0.0, 3, drug="phenylephrine", pump_max_ml_h=120.0)
    )
    for k in range(3):
        dev.send_tick(tick_inputs(k, 0.1 * k, 70.0 + k))
        drain(rt)
        x = rt.next_sample()
        rt.send_command(x.tick, 10.0 + k)
    rt.send_heartbeat(2, STATE_RUNNING)
    tlog.close()
    words = _readme_command()
    env = dict(os.environ)
    while "=" in words[0]:
        name, value = words.pop(0).split("=", 1)
        env[name] = value
    words = [exe if w == "mavlogdump.py" else w for w in words]
    words[-1] = str(tmp_path / "run.tlog")
    out = subprocess.run(words, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "UNKNOWN" not in out.stdout
    hello = r"PRESSOR_HELLO \{.*patient_seed : 7.*name : paper-tracking, drug : phenylephrine"
    assert re.search(hello + r".*pump_max_ml_h : 120\.0\}", out.stdout)  # extension fields too
    ticks = [int(t) for t in re.findall(r"MAP_SAMPLE \{sim_time_s : \S+ tick : (\d+),", out.stdout)]
    assert ticks == [0, 1, 2]
    assert re.search(r": HEARTBEAT \{type : 18, autopilot : 8, .*system_status : 4", out.stdout)
    assert len(re.findall(r"INFUSION_COMMAND \{tick : \d, rate_ml_h : 1[0-2]\.0", out.stdout)) == 3
