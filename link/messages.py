"""The typed messages of the pressor link, one per frame (or frame bundle), used by both ends.

The device (``hil_sim``) builds them and the runtime receives them: the same types on both sides,
so a value never changes shape between the world, the wire and the loop. Floats are float32 on the
wire (sim time is double); the world rounds to float32 before it builds a message, so a message
reads back from the wire exactly as it was sent.

The constants are the dialect's enums (``link/pressor.xml``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from pressor.link.dialect import pressor as mavlink

#: MAVLink role values (enum PRESSOR_ROLE), also the default system ids.
ROLE_RUNTIME = mavlink.PRESSOR_ROLE_RUNTIME
ROLE_DEVICE = mavlink.PRESSOR_ROLE_DEVICE

#: Command modes (enum PRESSOR_COMMAND_MODE).
MODE_AUTO = mavlink.PRESSOR_COMMAND_MODE_AUTO
MODE_SAFE = mavlink.PRESSOR_COMMAND_MODE_SAFE
MODE_STOP = mavlink.PRESSOR_COMMAND_MODE_STOP
MODE_MANUAL = mavlink.PRESSOR_COMMAND_MODE_MANUAL

#: Node states (enum PRESSOR_STATE).
STATE_BOOT = mavlink.PRESSOR_STATE_BOOT
STATE_RUNNING = mavlink.PRESSOR_STATE_RUNNING
STATE_FINISHED = mavlink.PRESSOR_STATE_FINISHED
STATE_FAULT = mavlink.PRESSOR_STATE_FAULT

#: Link modes (enum PRESSOR_LINK_MODE).
LINK_LOCKSTEP = mavlink.PRESSOR_LINK_MODE_LOCKSTEP
LINK_REALTIME = mavlink.PRESSOR_LINK_MODE_REALTIME

#: Why an end refuses its peer's hello (enum PRESSOR_REFUSAL_REASON).
REFUSAL_PROTOCOL_VERSION = mavlink.PRESSOR_REFUSAL_REASON_PROTOCOL_VERSION
REFUSAL_ROLE = mavlink.PRESSOR_REFUSAL_REASON_ROLE
REFUSAL_SYSTEM_ID = mavlink.PRESSOR_REFUSAL_REASON_SYSTEM_ID
REFUSAL_SAMPLE_PERIOD = mavlink.PRESSOR_REFUSAL_REASON_SAMPLE_PERIOD
REFUSAL_LINK_MODE = mavlink.PRESSOR_REFUSAL_REASON_LINK_MODE
REFUSAL_SENSOR_NOISE = mavlink.PRESSOR_REFUSAL_REASON_SENSOR_NOISE
REFUSAL_DRUG = mavlink.PRESSOR_REFUSAL_REASON_DRUG
REFUSAL_CONCENTRATION = mavlink.PRESSOR_REFUSAL_REASON_CONCENTRATION
REFUSAL_PUMP_MAXIMUM = mavlink.PRESSOR_REFUSAL_REASON_PUMP_MAXIMUM
REFUSAL_RUNTIME_CONFIG = mavlink.PRESSOR_REFUSAL_REASON_RUNTIME_CONFIG
REFUSAL_SIGNING = mavlink.PRESSOR_REFUSAL_REASON_SIGNING
#: longest refusal text (PRESSOR_REFUSAL.text is char[200])
REFUSAL_TEXT_CHARS = 200

#: Dialect semantics version both ends must announce (2: the hello carries drug, concentration and
#: pump maximum).
PROTOCOL_VERSION = 2


@dataclass(frozen=True, slots=True)
class Hello:
    """The announcement each end sends on connect (frame PRESSOR_HELLO).

    Attributes
    ----------
    name
        Scenario name (device) or controller name (runtime), at most 32 ASCII characters.
    patient_seed
        Seed of the simulated patient (device; 0 from the runtime).
    sample_period_s
        Sample period (s).
    sensor_noise_mmhg
        MAP sensor noise standard deviation (mmHg).
    n_ticks
        Ticks the device will send (0 = unbounded).
    link_mode
        ``LINK_LOCKSTEP`` or ``LINK_REALTIME``.
    role
        Sender's role (``ROLE_RUNTIME`` / ``ROLE_DEVICE``); filled in on receipt.
    protocol_version
        Dialect semantics version of the sender.
    drug
        Drug in the syringe (device) or the one the controller was designed for (runtime), at
        most 16 ASCII characters; empty when not announced.
    concentration_ug_ml
        Drug concentration (µg/ml): the syringe's (device) or the one the controller's gain
        units assume (runtime); 0 when not announced.
    pump_max_ml_h
        Largest rate (ml/h) the pump delivers (device) or the controller commands (runtime); 0
        when not announced.
    """

    name: str
    patient_seed: int = 0
    sample_period_s: float = 0.1
    sensor_noise_mmhg: float = 0.0
    n_ticks: int = 0
    link_mode: int = LINK_LOCKSTEP
    role: int = 0
    protocol_version: int = PROTOCOL_VERSION
    drug: str = ""
    concentration_ug_ml: float = 0.0
    pump_max_ml_h: float = 0.0


class Heartbeat(NamedTuple):
    """A peer's heartbeat (frame PRESSOR_HEARTBEAT): last tick handled and its ``STATE_*``.

    A named tuple: it also reads as the plain ``(tick, state)`` pair.
    """

    tick: int
    state: int


@dataclass(frozen=True, slots=True)
class TickInputs:
    """Everything the device reports for tick k (frames SCHEDULING_PARAMS, MAP_TARGET and
    MAP_SAMPLE, in any order): what the world observes and what the runtime's loop consumes.

    Attributes
    ----------
    tick
        Tick k of the MAP sample.
    sim_time_s
        Device time of the sample: k · sample period (s).
    map_mmhg
        Measured MAP (mmHg); NaN when the monitor has no valid value.
    quality
        Monitor quality flags (0 = good; :data:`pressor.contracts.faults` sensor-quality bits).
    target_mmhg
        The clinician's MAP target (mmHg); NaN on the runtime side if none received yet, or in
        lockstep when the runtime does not require it and the tick's own had not arrived.
    K, T_s, tau_s
        Scheduling parameters: sensitivity (mmHg/(ml/h)), lag (s), delay (s); NaN on the runtime
        side as for ``target_mmhg``.
    sched_valid
        The device marked the scheduling parameters valid.
    sched_tick, target_tick
        Tick the scheduling parameters / target belong to (-1 if none): equal to ``tick`` as the
        world builds it; on the runtime side in real time they differ when those frames were lost
        and the values are stale ones from an earlier tick (lockstep never hands over stale ones:
        see :class:`~pressor.link.runtime_session.RuntimeSession`).
    """

    tick: int
    sim_time_s: float
    map_mmhg: float
    quality: int
    target_mmhg: float
    K: float
    T_s: float
    tau_s: float
    sched_valid: bool
    sched_tick: int
    target_tick: int


@dataclass(frozen=True, slots=True)
class Command:
    """An infusion command (frame INFUSION_COMMAND): tick answered, rate (ml/h), ``MODE_*``."""

    tick: int
    rate_ml_h: float
    mode: int


@dataclass(frozen=True, slots=True)
class PumpStatus:
    """The pump after an advance to tick k (frame PUMP_STATUS).

    Attributes
    ----------
    tick
        The tick the world has advanced to.
    delivered_ml_h
        Rate flowing now (ml/h).
    volume_ml
        Volume delivered since the start (ml).
    alarms
        Pump alarm bit flags (:mod:`pressor.contracts.faults`).
    """

    tick: int
    delivered_ml_h: float
    volume_ml: float
    alarms: int
