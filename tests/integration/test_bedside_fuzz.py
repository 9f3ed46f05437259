"""The bedside loop under a fuzzing device: the real runtime loop (:class:`pressor.runtime.shell.loop.Loop`,
its boundary checks, supervisor, PI controller, signed :class:`link.RuntimeSession`) against a
device that sends, tick after tick, a seeded mix of good ticks and every bad input of issue 39 -
times that are NaN, backwards or ahead, tick numbers that jump (to 10^6 ahead), impossible MAP,
pump statuses and targets, mid-run hellos, the runtime's own frames echoed back, garbage, mutated,
duplicated and unsigned frames.

The device resends a tick that got no answer within 0.25 s (as a device's retransmit does) and
reports, per run: the frames it sent per category, the commands out of [0, 120] ml/h (must be 0),
the exceptions of the loop (0), and the longest wall time it waited for a command (<= 1 s).
``pytest -m slow -s tests/integration/test_bedside_fuzz.py`` prints the figures of a >= 10^5-frame
run.
"""

from __future__ import annotations

import io
import math
import random
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

import pytest

from pressor.baselines.pi import PIController
from pressor.link import (
    LINK_LOCKSTEP,
    STATE_FINISHED,
    DeviceSession,
    Hello,
    LinkClosedError,
    ManualClock,
    PeerRefused,
    PumpStatus,
    RuntimeSession,
    Signing,
)
from pressor.link.dialect import pressor as mavlink
from pressor.runtime.core.supervisor import Supervisor
from pressor.runtime.core.supervisor_config import supervisor_config_for
from pressor.runtime.shell.boundary import Boundary
from pressor.runtime.shell.loop import Loop
from tests.support.link_doubles import loop_pair

TS = 0.1
MAX = 120.0
SYRINGE = {"drug": "phenylephrine", "concentration_ug_ml": 100.0, "pump_max_ml_h": MAX}
ID_SAMPLE = mavlink.MAVLINK_MSG_ID_MAP_SAMPLE
ID_SCHED = mavlink.MAVLINK_MSG_ID_SCHEDULING_PARAMS
ID_TARGET = mavlink.MAVLINK_MSG_ID_MAP_TARGET
ID_STATUS = mavlink.MAVLINK_MSG_ID_PUMP_STATUS
#: the categories and their weights (a good tick most often, as on a real line)
CATEGORIES = {
    "good": 30,
    "time_nan": 2,
    "time_backwards": 2,
    "time_ahead": 2,
    "tick_jump": 1,
    "map_bad": 3,
    "status_bad": 3,
    "target_bad": 3,
    "sched_bad": 2,
    "hello_changed": 1,
    "hello_same": 1,
    "echo": 3,
    "garbage": 3,
    "mutated": 3,
    "duplicate": 2,
    "unsigned": 2,
}
_BAD_FLOATS = (math.nan, math.inf, -math.inf, 1e30, -5.0, 3.4e38, 0.0)


@dataclass
class FuzzReport:
    """What the fuzzing device saw."""

    frames: Counter = field(default_factory=Counter)
    commands: int = 0
    out_of_range: int = 0
    longest_gap_s: float = 0.0
    refusals: int = 0
    loop_error: BaseException | None = None
    ended: str = ""

    def total(self) -> int:
        return sum(self.frames.values())

    def lines(self) -> list[str]:
        rows = [f"  {k:<15} {v:>8}" for k, v in sorted(self.frames.items())]
        return [
            f"frames sent: {self.total()} in {len(self.frames)} categories",
            *rows,
            f"commands received: {self.commands}; out of [0, {MAX:g}] ml/h: {self.out_of_range}",
            f"exceptions in the loop: {0 if self.loop_error is None else 1} ({self.ended})",
            f"longest wait for a command: {self.longest_gap_s:.3f} s",
            f"mid-run hellos refused on the wire: {self.refusals}",
        ]


class _Recording(DeviceSession):
    """A device session that keeps the last bytes it read (the runtime's own, to echo back)."""

    heard = b""

    def feed(self, data: bytes) -> None:
        self.heard = (self.heard + data)[-4096:]
        super().feed(data)


class FuzzDevice:
    """A signed lockstep device sending a seeded mix of good and bad frames (see the module)."""

    def __init__(self, port, key: Signing, seed: int, report: FuzzReport) -> None:
        self.ep = _Recording(port, signing=key, clock=ManualClock())
        self.unsigned = DeviceSession(port, clock=ManualClock())  # the same line, no key
        self.rng = random.Random(seed)
        self.report = report
        self.ep.on_message = self._heard
        self.last_command_at = 0.0
        self.rate = 0.0

    def _heard(self, msg) -> None:
        if msg.get_type() == "INFUSION_COMMAND":
            r = self.report
            r.commands += 1
            if not (0.0 <= msg.rate_ml_h <= MAX):
                r.out_of_range += 1
            now = time.monotonic()
            r.longest_gap_s = max(r.longest_gap_s, now - self.last_command_at)
            self.last_command_at = now
            self.rate = msg.rate_ml_h

    def _send(self, category: str, msgid: int, *values, flush: bool = False) -> None:
        self.ep.send_fields(msgid, *values, flush=flush)
        self.report.frames[category] += 1

    def _raw(self, category: str, data: bytes) -> None:
        self.ep.flush()
        self.ep.port.write(data)
        self.report.frames[category] += 1

    def tick(self, k: int, category: str) -> None:
        """Tick ``k``'s frames with the fault of ``category`` (the tick's own frames count there)."""
        rng = self.rng
        self.ep.clock.t = k * TS
        t, map_mmhg, target = k * TS, 60.0 + 10.0 * rng.random(), 75.0
        status = (self.rate, 0)
        sched = (0.5, 150.0, 30.0, 1)
        if category == "time_nan":
            t = math.nan
        elif category == "time_backwards":
            t = max(0.0, k * TS - 5.0 - 10 * rng.random())
        elif category == "time_ahead":
            t = k * TS + 1.0 + 100 * rng.random()
        elif category == "map_bad":
            map_mmhg = rng.choice(_BAD_FLOATS)
        elif category == "status_bad":
            status = (rng.choice(_BAD_FLOATS), rng.randrange(1 << 16))
        elif category == "target_bad":
            target = rng.choice((*_BAD_FLOATS, 250.0, 20.0, 49.9, 120.1))
        elif category == "sched_bad":
            sched = (rng.choice(_BAD_FLOATS), rng.choice(_BAD_FLOATS), 30.0, rng.randrange(2))
        if k > 0:
            self._send(category, ID_STATUS, k, status[0], 0.0, status[1])
        self._send(category, ID_SCHED, k, *sched)
        self._send(category, ID_TARGET, k, target)
        self._send(category, ID_SAMPLE, t, k, map_mmhg, 0, flush=True)

    def noise(self, category: str) -> None:
        """The frames of a category that is not a tick of its own."""
        rng = self.rng
        if category == "hello_changed":
            self.ep.send_hello(
                Hello("fuzz", 0, TS, rng.choice((1000.0, 0.5)), 0, drug="norepinephrine")
            )
            self.report.frames[category] += 1
        elif category == "hello_same":
            self.ep.send_hello(Hello("fuzz", 0, TS, 0.0, 0, LINK_LOCKSTEP, **SYRINGE))
            self.report.frames[category] += 1
        elif category == "echo":
            self._raw(category, self.ep.heard[-300:])  # the runtime's own bytes, verbatim
        elif category == "garbage":
            self._raw(category, rng.randbytes(rng.randrange(1, 200)))
        elif category == "mutated":
            frame = bytearray(self.ep.codec.pack_fields(ID_SAMPLE, (0.0, 1, 70.0, 0)))
            frame[rng.randrange(len(frame))] ^= rng.randrange(1, 256)
            self._raw(category, bytes(frame))
        elif category == "unsigned":
            self.unsigned.send_fields(ID_TARGET, 0, 80.0)
            self.report.frames[category] += 1

    def wait(self, k: int) -> bool:
        """Wait 0.25 s for the command answering ``k``; a refusal of a mid-run hello is counted
        and the wait goes on."""
        while True:
            try:
                return self.ep.wait_for_command(k, 0.25) is not None
            except PeerRefused:
                self.report.refusals += 1
                self.ep.peer_refusal = None

    def run(self, n_frames: int) -> None:
        """Play ticks until ``n_frames`` frames were sent, then finish."""
        names, weights = list(CATEGORIES), list(CATEGORIES.values())
        self.ep.handshake(Hello("fuzz", 0, TS, 0.0, 0, LINK_LOCKSTEP, **SYRINGE), timeout_s=10.0)
        self.last_command_at = time.monotonic()
        k = 0
        while self.report.total() < n_frames:
            category = self.rng.choices(names, weights)[0]
            if category == "tick_jump" and k < 2**32 - 2 * 10**6:
                k += self.rng.choice((10, 1000, 10**5, 10**6))
            if category == "duplicate" and k > 0:
                self.tick(k - 1, category)
            elif category in ("good", "tick_jump", "duplicate") or category.startswith(
                ("time_", "map_", "status_", "target_", "sched_")
            ):
                self.tick(k, category)
            else:
                self.noise(category)
                self.tick(k, "good")
            while not self.wait(k):  # lost or unusable: the device resends the tick, clean
                self.tick(k, "good")
            k += 1
        self.ep.send_pump_status(PumpStatus(k, self.rate, 0.0, 0), flush=False)
        self.ep.send_heartbeat(k, STATE_FINISHED)


def fuzz(n_frames: int, seed: int) -> FuzzReport:
    """One fuzzing run of at least ``n_frames`` frames; the loop runs in a thread."""
    report = FuzzReport()
    a, b = loop_pair(buffer_size=1 << 20)
    key = Signing.generate(seed=seed)
    ep = RuntimeSession(a, signing=key)
    done = threading.Event()

    def runtime() -> None:
        try:
            peer = ep.handshake(Hello("pi"), timeout_s=10.0)
            ep.lock_terms()
            pi = PIController(TS)
            sup = Supervisor(supervisor_config_for(pi, peer.sensor_noise_mmhg))
            quiet = io.StringIO()  # one line per refused hello: counted by the device instead
            boundary = Boundary(TS, MAX, [], "fuzz", quiet, target_limits=(50.0, 120.0))
            loop = Loop(pi, sup, ep, history_ticks=4096, boundary=boundary)
            result = loop.run_lockstep(0, stall_timeout_s=30.0)
            report.loop_error, report.ended = result.error, result.ended
        except (LinkClosedError, BaseException) as exc:  # counted: the loop must never raise
            report.loop_error = exc
        finally:
            done.set()

    th = threading.Thread(target=runtime, daemon=True)
    th.start()
    FuzzDevice(b, key, seed, report).run(n_frames)
    done.wait(60.0)
    return report


def _check(report: FuzzReport, n_frames: int) -> None:
    print("\n" + "\n".join(report.lines()))
    assert report.total() >= n_frames
    assert set(report.frames) == set(CATEGORIES)  # every category was sent
    assert report.out_of_range == 0
    assert report.loop_error is None, report.loop_error
    assert report.ended == "device finished"
    assert report.longest_gap_s <= 1.0
    assert report.refusals >= 1


def test_the_loop_survives_a_fuzzing_device_and_never_leaves_the_pump_without_a_command():
    _check(fuzz(6000, seed=1), 6000)


@pytest.mark.slow
def test_slow_the_loop_survives_10_5_fuzzed_frames():
    _check(fuzz(100_000, seed=2), 100_000)
