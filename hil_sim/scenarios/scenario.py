"""Named, declarative SIL scenarios (TOML with units in the key names) and their validation.

A scenario file (``hil_sim/scenarios/NAME.toml``)::

    name = "paper-tracking"
    description = "one line"
    duration_s = 3600.0

    [patient]
    mode = "nonlinear"         # or "frozen" with K, T_s, tau_s, baseline_mmhg
    internal_step_s = 0.1

    [target]
    step_mmhg = 20.0           # target = baseline + step from step_time_s on (baseline before)
    step_time_s = 0.0

    [pump]                     # every key optional (PumpConfig defaults)
    max_rate_ml_h = 120.0

    [sensor]                   # every key optional
    noise_std_mmhg = 0.1
    [[sensor.artifacts]]
    kind = "flush"             # flush | damping | disconnect | monitor_fault
    start_s = 600.0
    duration_s = 5.0

    [[disturbances]]
    kind = "hemorrhage"        # hemorrhage | bolus | sinusoid
    start_s = 900.0
    ramp_s = 300.0
    depth_mmhg = 10.0

    [[faults]]                 # injected faults, as `--fault KIND:ARGS` (pressor.contracts.faults)
    kind = "sensor-flush"
    start_s = 600.0
    duration_s = 4.0

Every number is range-checked; unknown keys are errors. A bad file raises :class:`ScenarioError`
whose message is one line naming the file, the field, the value and the allowed range.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pressor.contracts.checks import allowed_range, check_range
from pressor.contracts.faults import FaultSpec, FaultSpecError, parse_fault_table
from pressor.hil_sim.devices.pump import PumpConfig
from pressor.hil_sim.devices.sensor import ARTIFACT_KINDS, Artifact, SensorConfig
from pressor.hil_sim.patients.patient import FrozenParams
from pressor.hil_sim.scenarios.disturbance import Bolus, Disturbance, Hemorrhage, Sinusoid

#: the shipped scenarios: the TOML files beside this module (package data)
SCENARIO_DIR = Path(__file__).resolve().parent
_REQUIRED = object()
_DAY_S = 86400.0


class ScenarioError(ValueError):
    """A scenario that cannot be loaded; the message names file, field, value and range."""


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes
    ----------
    name, description
        Identification.
    duration_s
        Run length (s).
    patient_mode
        ``"nonlinear"`` (seeded Table 1 patient) or ``"frozen"`` (``frozen`` parameters).
    frozen
        The LTI patient of a frozen scenario (else ``None``).
    internal_step_s
        Patient integration step (s).
    step_mmhg, step_time_s
        Target step above baseline (mmHg) and its time (s).
    target_mmhg
        An absolute target (mmHg) from ``step_time_s`` on, in place of ``baseline + step_mmhg``
        (the clinician's ``--target-mmhg``; the baseline before); ``None``: the relative step.
    pump, sensor
        Device configurations.
    disturbances
        Additive MAP disturbances (mmHg).
    source
        The file it came from.
    """

    name: str
    description: str
    duration_s: float
    patient_mode: str
    frozen: FrozenParams | None
    internal_step_s: float
    step_mmhg: float
    step_time_s: float
    pump: PumpConfig
    sensor: SensorConfig
    disturbances: tuple[Disturbance, ...] = ()
    faults: tuple[FaultSpec, ...] = ()
    source: str = field(default="<memory>", compare=False)
    target_mmhg: float | None = None

    @property
    def noisy(self) -> bool:
        """Whether the monitor adds noise (selects the 5 mmHg settling band)."""
        return self.sensor.noise_std_mmhg > 0.0


class _Reader:
    """Pulls typed, range-checked fields out of one TOML table, reporting dotted field names."""

    def __init__(self, file: str, table: Any, prefix: str) -> None:
        self.file = file
        self.prefix = prefix
        if not isinstance(table, dict):
            raise ScenarioError(f"{file}: field '{prefix.rstrip('.')}' = {table!r} must be a table")
        self.table = table
        self.used: set[str] = set()

    def fail(self, key: str, value: Any, allowed: str) -> ScenarioError:
        return ScenarioError(f"{self.file}: field '{self.prefix}{key}' = {value!r} {allowed}")

    def num(
        self,
        key: str,
        lo: float,
        hi: float,
        unit: str,
        default: Any = _REQUIRED,
        lo_open: bool = False,
    ) -> float:
        self.used.add(key)
        if key not in self.table:
            if default is _REQUIRED:
                allowed = allowed_range(lo, hi, lo_open=lo_open, unit=unit)
                raise self.fail(key, "missing", f"required, a finite number {allowed}")
            return default
        return check_range(
            f"{self.file}: field '{self.prefix}{key}'",
            self.table[key],
            lo,
            hi,
            lo_open=lo_open,
            unit=unit,
            error=ScenarioError,
        )

    def text(
        self, key: str, choices: tuple[str, ...] | None = None, default: Any = _REQUIRED
    ) -> str:
        self.used.add(key)
        if key not in self.table:
            if default is _REQUIRED:
                allowed = f"one of {list(choices)}" if choices else "a string"
                raise self.fail(key, "missing", f"required, {allowed}")
            return default
        v = self.table[key]
        if not isinstance(v, str) or (choices is not None and v not in choices):
            allowed = f"one of {list(choices)}" if choices else "a string"
            raise self.fail(key, v, f"must be {allowed}")
        return v

    def done(self) -> None:
        extra = sorted(set(self.table) - self.used)
        if extra:
            raise self.fail(extra[0], self.table[extra[0]], "unknown field")


def _disturbance(file: str, i: int, table: Any) -> Disturbance:
    r = _Reader(file, table, f"disturbances[{i}].")
    kind = r.text("kind", ("hemorrhage", "bolus", "sinusoid"))
    start = r.num("start_s", 0.0, _DAY_S, "s")
    d: Disturbance
    if kind == "hemorrhage":
        d = Hemorrhage(
            start, r.num("ramp_s", 0.0, _DAY_S, "s"), r.num("depth_mmhg", 0.0, 100.0, "mmHg")
        )
    elif kind == "bolus":
        d = Bolus(
            start,
            r.num("rise_s", 0.0, _DAY_S, "s", lo_open=True),
            r.num("amplitude_mmhg", 0.0, 100.0, "mmHg"),
            r.num("decay_s", 0.0, _DAY_S, "s", lo_open=True),
        )
    else:
        d = Sinusoid(
            start,
            r.num("amplitude_mmhg", 0.0, 50.0, "mmHg"),
            r.num("period_s", 1.0, _DAY_S, "s"),
            r.num("phase_deg", -360.0, 360.0, "deg", default=0.0),
        )
    r.done()
    return d


def _artifact(file: str, i: int, table: Any) -> Artifact:
    r = _Reader(file, table, f"sensor.artifacts[{i}].")
    kind = r.text("kind", ARTIFACT_KINDS)
    a = Artifact(
        kind=kind,
        start_s=r.num("start_s", 0.0, _DAY_S, "s"),
        duration_s=r.num("duration_s", 0.0, _DAY_S, "s", lo_open=True),
        level_mmhg=r.num("level_mmhg", -50.0, 400.0, "mmHg", default=math.nan),
        time_const_s=r.num("time_const_s", 0.0, 600.0, "s", default=20.0, lo_open=True),
        flag_after_s=r.num("flag_after_s", 0.0, _DAY_S, "s", default=math.inf),
    )
    r.done()
    return a


def parse_scenario(data: dict[str, Any], file: str = "<memory>") -> Scenario:
    """Validate a parsed TOML document into a :class:`Scenario` (raises :class:`ScenarioError`)."""
    top = _Reader(file, data, "")
    name = top.text("name")
    description = top.text("description", default="")
    duration = top.num("duration_s", 1.0, 7 * _DAY_S, "s")

    top.used.add("patient")
    p = _Reader(file, data.get("patient", {}), "patient.")
    mode = p.text("mode", ("nonlinear", "frozen"))
    step_s = p.num("internal_step_s", 0.001, 1.0, "s", default=0.1)
    frozen = None
    if mode == "frozen":
        frozen = FrozenParams(
            K=p.num("K", 0.0, 10.0, "mmHg/(ml/h)", lo_open=True),
            T_s=p.num("T_s", 1.0, 3600.0, "s"),
            tau_s=p.num("tau_s", 0.0, 600.0, "s"),
            baseline_mmhg=p.num("baseline_mmhg", 20.0, 150.0, "mmHg"),
        )
    p.done()

    top.used.add("target")
    t = _Reader(file, data.get("target", {}), "target.")
    step_mmhg = t.num("step_mmhg", -60.0, 60.0, "mmHg")
    step_time = t.num("step_time_s", 0.0, duration, "s", default=0.0)
    t.done()

    top.used.add("pump")
    pr = _Reader(file, data.get("pump", {}), "pump.")
    max_rate = pr.num("max_rate_ml_h", 0.0, 10000.0, "ml/h", default=120.0, lo_open=True)
    occ_start = pr.num("occlusion_start_s", 0.0, _DAY_S * 7, "s", default=None)
    pump = PumpConfig(
        max_rate_ml_h=max_rate,
        resolution_ml_h=pr.num("resolution_ml_h", 0.0, 10.0, "ml/h", default=0.0),
        latency_s=pr.num("latency_s", 0.0, 60.0, "s", default=0.0),
        watchdog_s=pr.num("watchdog_s", 0.0, 3600.0, "s", default=5.0, lo_open=True),
        safe_rate_ml_h=pr.num("safe_rate_ml_h", 0.0, max_rate, "ml/h", default=0.0),
        reservoir_ml=pr.num("reservoir_ml", 0.0, 10000.0, "ml", default=1000.0, lo_open=True),
        occlusion_start_s=occ_start,
        occlusion_duration_s=pr.num(
            "occlusion_duration_s", 0.0, 7 * _DAY_S, "s", default=math.inf, lo_open=True
        ),
    )
    pr.done()

    top.used.add("sensor")
    sensor_table = data.get("sensor", {})
    sr = _Reader(file, sensor_table, "sensor.")
    sr.used.add("artifacts")
    raw_artifacts = sensor_table.get("artifacts", []) if isinstance(sensor_table, dict) else []
    if not isinstance(raw_artifacts, list):
        raise sr.fail("artifacts", raw_artifacts, "must be an array of tables [[sensor.artifacts]]")
    sensor = SensorConfig(
        period_s=sr.num("period_s", 0.0, 60.0, "s", default=0.1, lo_open=True),
        quantum_mmhg=sr.num("quantum_mmhg", 0.0, 10.0, "mmHg", default=0.0),
        noise_std_mmhg=sr.num("noise_std_mmhg", 0.0, 50.0, "mmHg", default=0.0),
        artifacts=tuple(_artifact(file, i, a) for i, a in enumerate(raw_artifacts)),
    )
    sr.done()

    top.used.add("disturbances")
    raw_dist = data.get("disturbances", [])
    if not isinstance(raw_dist, list):
        raise top.fail("disturbances", raw_dist, "must be an array of tables [[disturbances]]")
    disturbances = tuple(_disturbance(file, i, d) for i, d in enumerate(raw_dist))
    top.used.add("faults")
    raw_faults = data.get("faults", [])
    if not isinstance(raw_faults, list):
        raise top.fail("faults", raw_faults, "must be an array of tables [[faults]]")
    try:
        faults = tuple(parse_fault_table(f, file, i, i) for i, f in enumerate(raw_faults))
    except FaultSpecError as exc:
        raise ScenarioError(str(exc)) from None
    top.done()
    return Scenario(
        name=name,
        description=description,
        duration_s=duration,
        patient_mode=mode,
        frozen=frozen,
        internal_step_s=step_s,
        step_mmhg=step_mmhg,
        step_time_s=step_time,
        pump=pump,
        sensor=sensor,
        disturbances=disturbances,
        faults=faults,
        source=file,
    )


def load_scenario_file(path: str | Path) -> Scenario:
    """Load and validate one scenario file (raises :class:`ScenarioError`)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read scenario file: {exc.strerror}") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from exc
    return parse_scenario(data, str(path))


def scenario_names() -> list[str]:
    """Names of the shipped scenarios, sorted."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def is_scenario_path(name_or_path: str | Path) -> bool:
    """Whether ``--scenario`` names a file (a ``.toml`` name or a path) rather than a shipped one."""
    s = str(name_or_path)
    return s.endswith(".toml") or "/" in s


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A shipped scenario by name, or any scenario file by path (``.toml``; relative paths are
    relative to the working directory)."""
    s = str(name_or_path)
    if is_scenario_path(s):
        return load_scenario_file(s)
    path = SCENARIO_DIR / f"{s}.toml"
    if not path.is_file():
        raise ScenarioError(f"--scenario: field 'name' = {s!r} must be one of {scenario_names()}")
    return load_scenario_file(path)
