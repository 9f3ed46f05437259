"""The device side of the loop: patient + pump + MAP monitor + disturbances + the clinician's target.

Pure core, stepped in lockstep by its caller (the in-process simulator :mod:`pressor.hil_sim.episode` or
the serial-link device process ``pressor.hil_sim.devices.device``); the order per tick k is::

    obs = world.observe()            # tick k: measured MAP, target, scheduling truth
    u = core.step(obs, ...)          # supervisor + controller (pressor.runtime.core.closed_loop), or the
                                     # runtime at the far end of the link
    world.apply_command(u)           # the command answering tick k
    status = world.advance()         # integrate one sample period -> tick k + 1

Everything the world emits (observation and pump status fields) and every command it receives is
rounded to float32, the precision of the serial link, so the in-process simulator and the serial SIL
see the same numbers and produce the same trajectory bit for bit. Scheduling parameters (K, T, τ)
are the patient's truth (the paper's "parameter generation" block; an estimator replaces it later).
Random numbers (sensor noise) come from the patient's own seeded stream, so a trajectory depends only
on (scenario, patient_seed, sample period, commands).

The patient is any :class:`pressor.hil_sim.patients.patient_model.PatientModel` (``patient_model=``, a
registry name or ``MODULE:CLASS``; default the paper's model, :class:`pressor.hil_sim.patients.patient.Patient`);
a frozen scenario fixes the paper model's LTI mode and takes no other model.

Faults (``faults=``, plus the scenario's own ``[[faults]]``) are injected here for the sensor, the
pump and the scheduling parameters (:class:`pressor.hil_sim.scenarios.faults.WorldFaults`); link faults belong
to the device process. A world without faults behaves exactly as before.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from pressor.hil_sim.devices.pump import Pump
from pressor.hil_sim.devices.sensor import Sensor
from pressor.hil_sim.patients.cohort import patient_rng
from pressor.hil_sim.patients.patient import FrozenParams, Patient, PatientParams
from pressor.hil_sim.patients.patient_model import (
    DEFAULT_PATIENT_MODEL,
    PatientModel,
    check_model_for_scenario,
)
from pressor.hil_sim.scenarios.disturbance import DisturbanceSum
from pressor.hil_sim.scenarios.faults import WorldFaults
from pressor.hil_sim.scenarios.scenario import Scenario, load_scenario
from pressor.link.messages import PumpStatus, TickInputs

_F32 = struct.Struct("<f")
#: the six floats of an observation and the two of a pump status, rounded in one pack/unpack each
#: (per tick: the same rounding as six or two calls of :func:`f32`, at a fraction of the calls)
_F32x6 = struct.Struct("<6f")
_F32x2 = struct.Struct("<2f")


#: TickInputs and PumpStatus are frozen, slotted dataclasses: their ``__init__`` sets each field
#: through ``object.__setattr__`` (~0.1 µs a field, ~1.9 µs a tick for the two). The world builds
#: one of each every tick, so :func:`_tick_inputs` and :func:`_pump_status` fill a bare instance
#: through the slots' own descriptors (~0.05 µs a field): the same object, equal to the
#: constructor's (tests/hil_sim/test_world.py); each setter is named by its field.
_new_object = object.__new__


def _setter(cls: type, field: str) -> Callable[[object, Any], None]:
    """The ``__set__`` of the slot descriptor of ``cls``'s ``field``."""
    return getattr(cls, field).__set__


_ti_tick, _ti_time = _setter(TickInputs, "tick"), _setter(TickInputs, "sim_time_s")
_ti_map, _ti_quality = _setter(TickInputs, "map_mmhg"), _setter(TickInputs, "quality")
_ti_target, _ti_valid = _setter(TickInputs, "target_mmhg"), _setter(TickInputs, "sched_valid")
_ti_K, _ti_T, _ti_tau = (_setter(TickInputs, f) for f in ("K", "T_s", "tau_s"))
_ti_sched_tick, _ti_target_tick = (_setter(TickInputs, f) for f in ("sched_tick", "target_tick"))
_ps_tick, _ps_delivered = _setter(PumpStatus, "tick"), _setter(PumpStatus, "delivered_ml_h")
_ps_volume, _ps_alarms = _setter(PumpStatus, "volume_ml"), _setter(PumpStatus, "alarms")


def _tick_inputs(
    tick: int,
    sim_time_s: float,
    map_mmhg: float,
    quality: int,
    target_mmhg: float,
    K: float,
    T_s: float,
    tau_s: float,
    sched_valid: bool,
    sched_tick: int,
    target_tick: int,
) -> TickInputs:
    """``TickInputs(tick, sim_time_s, ...)``, built at half the constructor's cost (see above)."""
    obs = _new_object(TickInputs)
    _ti_tick(obs, tick)
    _ti_time(obs, sim_time_s)
    _ti_map(obs, map_mmhg)
    _ti_quality(obs, quality)
    _ti_target(obs, target_mmhg)
    _ti_K(obs, K)
    _ti_T(obs, T_s)
    _ti_tau(obs, tau_s)
    _ti_valid(obs, sched_valid)
    _ti_sched_tick(obs, sched_tick)
    _ti_target_tick(obs, target_tick)
    return obs


def _pump_status(tick: int, delivered_ml_h: float, volume_ml: float, alarms: int) -> PumpStatus:
    """``PumpStatus(tick, delivered_ml_h, volume_ml, alarms)``, built as :func:`_tick_inputs`."""
    status = _new_object(PumpStatus)
    _ps_tick(status, tick)
    _ps_delivered(status, delivered_ml_h)
    _ps_volume(status, volume_ml)
    _ps_alarms(status, alarms)
    return status


@functools.lru_cache(maxsize=8)
def disturbance_ticks(parts: tuple, period_s: float, n_ticks: int) -> tuple[float, ...]:
    """The scenario disturbances' sum (mmHg) at every tick k < ``n_ticks`` of period ``period_s``
    (s), computed as the world computes it (at ``k * period_s``), so reading the table gives the
    same bits. Every patient of a cohort meets the same disturbances: a worker process computes
    them once per scenario instead of once per tick of every patient."""
    total = DisturbanceSum(parts)
    return tuple(total(k * period_s) for k in range(n_ticks))


def f32(x: float, _pack=_F32.pack, _unpack=_F32.unpack) -> float:
    """``x`` rounded to the nearest float32 (as it would cross the serial link); ±inf on overflow."""
    try:
        return _unpack(_pack(x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


class World:
    """Patient, pump, monitor and target for one scenario and one patient seed.

    Parameters
    ----------
    scenario
        A :class:`~pressor.hil_sim.scenarios.scenario.Scenario` or a scenario name / path.
    patient_seed
        Seed of the patient (coefficients and monitor noise); ignored for the coefficients of a
        frozen scenario.
    sample_period_s
        Loop period (s); a whole multiple of the scenario's internal patient step.
    faults
        Extra injected faults (:class:`pressor.contracts.faults.FaultSpec`), after the scenario's own.
    patient_model
        The patient model: a :data:`pressor.hil_sim.patients.patient_model.PATIENT_MODELS` name or
        ``MODULE:CLASS``.

    Raises
    ------
    pressor.hil_sim.patients.patient_model.PatientModelError
        A model that cannot be loaded, or a frozen scenario with a model other than ``paper``.
    """

    def __init__(
        self,
        scenario: Scenario | str,
        patient_seed: int,
        sample_period_s: float = 0.1,
        faults: tuple = (),
        patient_model: str = DEFAULT_PATIENT_MODEL,
    ) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        sc = self.scenario
        if not 0.0 < sample_period_s <= 10.0:
            raise ValueError(f"sample_period_s={sample_period_s!r} outside (0, 10] s")
        n_sub = round(sample_period_s / sc.internal_step_s)
        if n_sub < 1 or abs(n_sub * sc.internal_step_s - sample_period_s) > 1e-9 * sample_period_s:
            raise ValueError(
                f"sample_period_s={sample_period_s} s is not a whole multiple of the scenario's"
                f" patient.internal_step_s={sc.internal_step_s} s"
            )
        self.sample_period_s = float(sample_period_s)
        self.patient_seed = int(patient_seed)
        self._model = check_model_for_scenario(patient_model, sc.name, sc.frozen is not None)
        self.patient_model = patient_model
        self._h = sample_period_s / n_sub
        self._n_sub = n_sub
        self.patient: PatientModel = self.fresh_patient(self._h)
        params = getattr(self.patient, "params", None)
        #: the paper model's coefficients (None for another model: see ``patient.coefficients()``)
        self.params = params if isinstance(params, (PatientParams, FrozenParams)) else None
        self.pump = Pump(sc.pump)
        self.fault_specs = (*sc.faults, *faults)
        self.faults = WorldFaults(self.fault_specs, self.sample_period_s)
        sensor_cfg = sc.sensor
        if self.faults.artifacts:
            sensor_cfg = replace(
                sensor_cfg, artifacts=(*sensor_cfg.artifacts, *self.faults.artifacts)
            )
        self._sched_faults = bool(self.faults.sched)
        self._pump_faults = bool(self.faults.pump)
        self.sensor = Sensor(sensor_cfg, patient_rng(patient_seed, 1))
        self.disturbance = DisturbanceSum(sc.disturbances)
        n_ticks = round(sc.duration_s / self.sample_period_s) + 1
        self._disturbance_ticks = disturbance_ticks(
            tuple(sc.disturbances), self.sample_period_s, n_ticks
        )
        self.baseline_mmhg = self.patient.baseline_mmhg
        self.tick = 0
        self.last_command_ml_h = math.nan
        self.last_mean_rate_ml_h = 0.0
        self._obs: TickInputs | None = None
        self._true_map = math.nan

    # -- the pinned API ---------------------------------------------------------------------------
    @property
    def sim_time_s(self) -> float:
        """Time of the current tick (s)."""
        return self.tick * self.sample_period_s

    def target_at(self, t_s: float) -> float:
        """The clinician's target (mmHg) at ``t_s``: baseline, then baseline + step from t0 (the
        scenario's absolute ``target_mmhg`` instead, when it has one)."""
        sc = self.scenario
        if t_s < sc.step_time_s - 1e-9:
            return self.baseline_mmhg
        return self.baseline_mmhg + sc.step_mmhg if sc.target_mmhg is None else sc.target_mmhg

    @property
    def step_mmhg(self) -> float:
        """This patient's target step (mmHg): the scenario's, or its absolute target minus this
        patient's baseline."""
        sc = self.scenario
        return sc.step_mmhg if sc.target_mmhg is None else sc.target_mmhg - self.baseline_mmhg

    def true_map_mmhg(self) -> float:
        """True MAP now (mmHg): baseline + ΔMAP + disturbances."""
        if self._obs is not None and self._obs.tick == self.tick:
            return self._true_map
        return self.patient.map_mmhg + self._disturbance_at(self.tick)

    def _disturbance_at(self, tick: int) -> float:
        """The disturbances (mmHg) at ``tick``: the cohort's table, past its end computed."""
        table = self._disturbance_ticks
        return table[tick] if tick < len(table) else self.disturbance(tick * self.sample_period_s)

    def observe(self) -> TickInputs:
        """The observation of the current tick (computed once per tick; repeated calls agree)."""
        obs = self._obs
        if obs is not None and obs.tick == self.tick:
            return obs
        tick = self.tick
        t = tick * self.sample_period_s  # sim_time_s
        p = self.patient
        table = self._disturbance_ticks  # _disturbance_at(tick), without a call a tick
        disturbance = table[tick] if tick < len(table) else self.disturbance(t)
        self._true_map = true_map = p.map_mmhg + disturbance
        reading, quality = self.sensor.read(t, true_map)
        K, T_s, tau_s, valid = p.K, p.T_s, p.tau_s, True
        if self._sched_faults:
            K, T_s, tau_s, valid = self.faults.scheduling(tick, K, T_s, tau_s, valid)
        target = self.target_at(t)
        try:
            t32, reading32, target32, K32, T32, tau32 = _F32x6.unpack(
                _F32x6.pack(t, reading, target, K, T_s, tau_s)
            )
        except OverflowError:  # one of them beyond float32: each on its own (±inf)
            t32, reading32, target32 = f32(t), f32(reading), f32(target)
            K32, T32, tau32 = f32(K), f32(T_s), f32(tau_s)
        obs = _tick_inputs(
            tick, t32, reading32, quality, target32, K32, T32, tau32, valid, tick, tick
        )
        self._obs = obs
        return obs

    def apply_command(self, rate_ml_h: float) -> None:
        """Receive the infusion command (ml/h) answering the current tick (float32-rounded)."""
        if self._obs is None or self._obs.tick != self.tick:
            self.observe()  # the monitor samples every tick whether or not anyone asked
        try:  # f32(rate_ml_h), without its call
            cmd = _F32.unpack(_F32.pack(rate_ml_h))[0]
        except OverflowError:
            cmd = f32(rate_ml_h)
        self.last_command_ml_h = cmd
        if self._pump_faults and self.faults.pump_state(self.tick)[2]:
            self.pump.feed_watchdog()  # pump-ignore: acknowledged, not applied
        else:
            self.pump.command(cmd)

    def advance(self) -> PumpStatus:
        """Integrate one sample period (pump, then patient, per internal step); tick k → k + 1."""
        if self._obs is None or self._obs.tick != self.tick:
            self.observe()
        pump, patient, h = self.pump, self.patient, self._h
        if self._pump_faults:
            occ, empty, _, factor = self.faults.pump_state(self.tick)
            pump.inject(occ, empty, factor)
        total = 0.0
        for _ in range(self._n_sub):
            mean = pump.advance(h)
            patient.step(mean)
            total += mean
        self.last_mean_rate_ml_h = total / self._n_sub
        self.tick += 1
        delivered, volume = pump.delivered_ml_h, pump.volume_ml
        try:
            delivered32, volume32 = _F32x2.unpack(_F32x2.pack(delivered, volume))
        except OverflowError:
            delivered32, volume32 = f32(delivered), f32(volume)
        return _pump_status(self.tick, delivered32, volume32, pump.alarms)

    def fresh_patient(self, step_s: float) -> PatientModel:
        """A new copy of this world's patient, at rest, stepped every ``step_s`` s (the world's own
        is the one at ``sample_period_s`` over its internal steps)."""
        sc = self.scenario
        if sc.frozen is not None:
            return Patient(sc.frozen, step_s)
        return self._model.from_seed(self.patient_seed, step_s)

    def truth(self) -> dict[str, float | int]:
        """Ground truth now, for recording only (never for control)."""
        p = self.patient
        return {
            "tick": self.tick,
            "sim_time_s": self.sim_time_s,
            "map_mmhg": self.true_map_mmhg(),
            "delta_map_mmhg": p.delta_map_mmhg,
            "disturbance_mmhg": self.disturbance(self.sim_time_s),
            "baseline_mmhg": self.baseline_mmhg,
            "target_mmhg": self.target_at(self.sim_time_s),
            "K": p.K,
            "T_s": p.T_s,
            "tau_s": p.tau_s,
            "pump_rate_ml_h": self.pump.delivered_ml_h,
            "mean_rate_ml_h": self.last_mean_rate_ml_h,
            "volume_ml": self.pump.volume_ml,
            "pump_alarms": self.pump.alarms,
        }

    # -- scenario-level facts ---------------------------------------------------------------------
    def required_delta_mmhg(self) -> float:
        """Largest ΔMAP (mmHg) the target asks of the drug over the scenario (disturbances included)."""
        sc = self.scenario
        need = self.need_mmhg(np.arange(sc.step_time_s, sc.duration_s + 1.0, 1.0))
        return float(need.max()) if need.size else 0.0

    def need_mmhg(self, t_s: np.ndarray) -> np.ndarray:
        """The rise (mmHg) the target asks of the drug at each time ``t_s`` (s): target minus
        baseline minus the scenario's disturbance."""
        return np.array([self.target_at(t) - self.baseline_mmhg - self.disturbance(t) for t in t_s])

    def reachable(self, max_rate_ml_h: float | None = None) -> bool:
        """Whether the pump's maximum rate (or ``max_rate_ml_h``, ml/h: a lower dose limit) can
        bring MAP within the metrics' band of the target at this patient's sensitivity
        (:func:`pressor.contracts.metrics.reachable_band_mmhg`: the scenario's settling band, or the
        clinical band without a target step), on the steady state of that rate. Whether the rate
        also holds it there for the scenario's hour: :func:`pressor.hil_sim.reach.holds`."""
        sc = self.scenario
        top = sc.pump.max_rate_ml_h if max_rate_ml_h is None else max_rate_ml_h
        achievable = self.patient.max_delta_map_mmhg(top)
        return self.required_delta_mmhg() - self.band_mmhg() <= achievable

    def band_mmhg(self) -> float:
        """The band (mmHg) around the target a reached patient is within: the metrics' settling
        band of the scenario's step, or the clinical band without one
        (:func:`pressor.contracts.metrics.reachable_band_mmhg`)."""
        from pressor.contracts.metrics import reachable_band_mmhg

        step = self.step_mmhg
        return reachable_band_mmhg(step if step != 0.0 else None, self.scenario.noisy)
