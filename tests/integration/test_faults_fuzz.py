"""Property-based: random and mutated byte streams never raise in the link parser and never make the
runtime or the device command outside [0, pump max].

The fast variant runs a few thousand examples per target in CI; the ``slow`` one runs >= 10^5 in
total (``pytest -m slow tests/integration/test_faults_fuzz.py``).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pressor.baselines.pi import PIController
from pressor.hil_sim.world import World
from pressor.link import DeviceSession, RuntimeSession, Signing
from pressor.link.dialect import pressor as mavlink
from pressor.runtime.core.closed_loop import CLEAN_LINK, ClosedLoopCore
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import supervisor_config_for
from tests.support.link_doubles import loop_pair

MAX = 120.0
_f32 = st.one_of(
    st.floats(width=32, allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -1.0, 1e30, -1e30, 80.0, 300.0, math.nan, math.inf, -math.inf]),
)
_u32 = st.integers(0, 2**32 - 1)


def _frame(mav, kind, vals):
    if kind == 0:
        return mav.map_sample_encode(vals[0] % 1e9, vals[5], vals[1], vals[6] & 0xFFFF)
    if kind == 1:
        return mav.scheduling_params_encode(vals[5], vals[1], vals[2], vals[3], vals[6] & 1)
    if kind == 2:
        return mav.map_target_encode(vals[5], vals[1])
    if kind == 3:
        return mav.infusion_command_encode(vals[5], vals[1], vals[6] & 3)
    if kind == 4:
        return mav.pump_status_encode(vals[5], vals[1], vals[2], vals[6] & 0xFFFF)
    return mav.pressor_heartbeat_encode(vals[5], vals[6] & 3, vals[6] & 3)


@st.composite
def streams(draw):
    """Valid frames with arbitrary field values (NaN, inf, huge), then mutated, or pure noise."""
    if draw(st.integers(0, 4)) == 0:
        return draw(st.binary(max_size=400))
    # from the device (2), from the runtime (1: an echo to the runtime, the runtime's own to the
    # device) or a third node: each end drops the frames of another system id than its peer's
    mav = mavlink.MAVLink(None, draw(st.sampled_from([2, 1, 7])), 1)
    if draw(st.booleans()):
        mav.signing.secret_key = Signing.generate(seed=draw(st.integers(0, 1))).key
        mav.signing.sign_outgoing = True
    out = bytearray()
    for _ in range(draw(st.integers(1, 8))):
        vals = [draw(_f32) for _ in range(4)]
        vals += [draw(st.floats(-1e12, 1e12)), draw(_u32), draw(st.integers(0, 2**16 - 1))]
        msg = _frame(mav, draw(st.integers(0, 5)), [vals[4], *vals[:3], 0, vals[5], vals[6]])
        out += msg.pack(mav)
    for _ in range(draw(st.integers(0, 6))):  # mutations: flip, insert, delete, splice
        op = draw(st.integers(0, 3))
        i = draw(st.integers(0, max(0, len(out) - 1)))
        if op == 0 and out:
            out[i] ^= draw(st.integers(1, 255))
        elif op == 1:
            out[i:i] = draw(st.binary(min_size=1, max_size=20))
        elif op == 2 and out:
            del out[i : i + draw(st.integers(1, 20))]
        else:
            j = draw(st.integers(0, max(0, len(out) - 1)))
            out[i:i] = out[j : j + draw(st.integers(1, 40))]
    return bytes(out)


def runtime_side(data: bytes) -> None:
    """Runtime parser + closed-loop core: never raises, commands stay in [0, MAX]."""
    a, _ = loop_pair()
    ep = RuntimeSession(a, complete_ticks=False)
    third = len(data) // 3  # two reads, as a port would deliver them
    ep.feed(data[:third])
    ep.feed(data[third:])
    pi = PIController(0.1)
    core = ClosedLoopCore(pi, Supervisor(supervisor_config_for(pi, 0.0)))
    t = 0.0
    while (x := ep.next_sample()) is not None:
        t += 0.1
        u = core.step(x, t, ep.pump_status, CLEAN_LINK).command_ml_h
        assert 0.0 <= u <= MAX and math.isfinite(u)


_WORLD = World("paper-tracking", 1, 0.1)


def device_side(data: bytes) -> None:
    """Device parser + pump: whatever command got through, delivery stays in [0, pump max]."""
    a, _ = loop_pair()
    ep = DeviceSession(a)
    ep.feed(data)
    pump = _WORLD.pump
    for cmd in ep._commands:
        pump.command(cmd.rate_ml_h)
        pump.advance(0.1)
        assert 0.0 <= pump.delivered_ml_h <= pump.config.max_rate_ml_h
        assert 0.0 <= pump.rate_ml_h <= pump.config.max_rate_ml_h
    ep._commands.clear()


def _fuzz(n: int):
    return settings(
        max_examples=n,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )


@_fuzz(500)
@given(streams())
def test_runtime_parser_and_supervisor_survive_fuzzed_streams(data):
    runtime_side(data)


@_fuzz(500)
@given(streams())
def test_device_parser_and_pump_survive_fuzzed_streams(data):
    device_side(data)


def test_a_valid_out_of_range_command_frame_is_clamped_by_the_pump():
    mav = mavlink.MAVLink(None, 1, 1)
    before = _WORLD.pump.commands_out_of_range  # the fuzz tests share this pump
    for rate in (500.0, -3.0, math.inf, math.nan, 1e30):
        frame = mav.infusion_command_encode(0, rate, 0).pack(mav)
        device_side(frame)
    assert _WORLD.pump.commands_out_of_range - before >= 3


@pytest.mark.slow
@_fuzz(50_000)
@given(streams())
def test_slow_runtime_side_50k_streams(data):
    runtime_side(data)


@pytest.mark.slow
@_fuzz(50_000)
@given(streams())
def test_slow_device_side_50k_streams(data):
    device_side(data)
