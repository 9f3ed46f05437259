"""Drug-bound designs, the drug library and the supervisor's dose limits (docs/DRUGS.md).

Dose conversion at the boundary values, every library field's validation, the hard limit never
exceeded under any controller output (hypothesis), the soft limit's alarm, the hourly maximum over
a sliding hour, and the binding from the design TOML through the artifact to the generated module.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pressor.contracts.drug import (
    DEFAULT_BINDING,
    DrugBinding,
    binding_of,
    dose_ug_kg_min,
    dose_ug_min,
)
from pressor.plumbing.usage import UsageError
from pressor.runtime.core.dose_guard import (
    DOSE_HARD_LIMIT,
    DOSE_HOUR_LIMIT,
    DOSE_SHORTFALL,
    DOSE_SOFT_LIMIT,
    DoseGuard,
)
from pressor.runtime.core.supervisor import Supervisor, SupervisorInput
from pressor.runtime.core.supervisor_config import Fault, State, SupervisorConfig
from pressor.runtime.inputs.clinician import ClinicianInput
from pressor.runtime.inputs.dosing import bind_syringe, dose_summary, parse_weight
from pressor.runtime.inputs.drug_library import (
    WEIGHT_MAX_KG,
    WEIGHT_MIN_KG,
    DoseLimits,
    DrugLibraryError,
    default_library_path,
    load_library,
)

TS = 0.1


# -- dose conversion -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("rate", "conc", "weight", "ug_min", "ug_kg_min"),
    [
        (0.0, 100.0, 70.0, 0.0, 0.0),
        (120.0, 100.0, 70.0, 200.0, 200.0 / 70.0),  # the design's maximum, phenylephrine
        (1.0, 16.0, 70.0, 16.0 / 60.0, 16.0 / 4200.0),  # LITERATURE: ~0.0038 ug/kg/min
        (120.0, 100.0, WEIGHT_MIN_KG, 200.0, 200.0 / 30.0),
        (120.0, 100.0, WEIGHT_MAX_KG, 200.0, 0.8),
        (10000.0, 100000.0, WEIGHT_MIN_KG, 1e9 / 60.0, 1e9 / 1800.0),
    ],
)
def test_dose_conversion_at_the_boundaries(rate, conc, weight, ug_min, ug_kg_min):
    assert dose_ug_min(rate, conc) == pytest.approx(ug_min, rel=1e-12)
    assert dose_ug_kg_min(rate, conc, weight) == pytest.approx(ug_kg_min, rel=1e-12)
    assert 16.0 / 4200.0 == pytest.approx(0.0038, abs=1e-4)


@pytest.mark.parametrize("text", ["30", "250", "70.5"])
def test_weight_in_range_is_accepted(text):
    assert parse_weight(text) == float(text)


@pytest.mark.parametrize("text", ["29.999", "250.001", "nan", "inf", "-70", "abc"])
def test_weight_out_of_range_is_refused_naming_the_range(text):
    with pytest.raises(
        ValueError, match=rf"^{text!r}.*: must be a finite number in \[30, 250\] kg$"
    ):
        parse_weight(text)


# -- the library file -------------------------------------------------------------------------------
def test_shipped_library_has_both_drugs_with_consistent_limits():
    lib = load_library()
    phe, nor = lib["phenylephrine"], lib["norepinephrine"]
    assert (phe.unit, phe.hard_max, phe.soft_max, phe.max_per_hour) == ("ug/min", 200, 100, 6000)
    assert 100.0 in phe.concentrations_ug_ml
    assert (nor.unit, nor.hard_max, nor.soft_max) == ("ug/kg/min", 1.0, 0.5)
    assert nor.concentrations_ug_ml == (16.0, 32.0, 64.0)
    # the shipped phenylephrine design's 120 ml/h is exactly the hard maximum at 100 ug/ml
    assert phe.limits(100.0, None).hard_max_ml_h == 120.0


def _write(tmp_path, body: str):
    p = tmp_path / "lib.toml"
    p.write_text("format_version = 1\n" + body)
    return p


GOOD = """[drugs.x]
concentrations_ug_ml = [10.0]
hard_max_ug_min = 100.0
soft_max_ug_min = 50.0
max_ug_per_hour = 3000.0
"""


@pytest.mark.parametrize(
    ("edit", "field", "allowed"),
    [
        (("10.0]", "0.0]"), "drugs.x.concentrations_ug_ml", "(0, 100000]"),
        (("[10.0]", "[]"), "drugs.x.concentrations_ug_ml", "a list of 1 to 20"),
        (("hard_max_ug_min = 100.0", "hard_max_ug_min = -1"), "drugs.x.hard_max_ug_min", "(0,"),
        (("hard_max_ug_min = 100.0", "hard_max_ug_min = nan"), "drugs.x.hard_max_ug_min", "(0,"),
        (("soft_max_ug_min = 50.0", "soft_max_ug_min = 150.0"), "drugs.x.soft_max_ug_min", "100"),
        (("3000.0", "2999.0"), "drugs.x.max_ug_per_hour", "[60 x soft_max_ug_min = 3000"),
        (("max_ug_per_hour", "max_ug_kg_per_hour"), "drugs.x", "exactly one of"),
        (("soft_max_ug_min = 50.0\n", ""), "drugs.x.soft_max_ug_min", "given"),
        (("[drugs.x]", "[drugs.X]"), "drugs.X", "lower-case"),
        (("hard_max_ug_min = 100.0", "hard_max_ug_min = true"), "drugs.x.hard_max_ug_min", "(0,"),
        (("max_ug_per_hour = 3000.0", "max_ug_per_hour = 3000.0\nrate = 1"), "drugs.x.rate", "one"),
    ],
)
def test_every_library_field_is_checked_naming_file_field_value_and_range(
    tmp_path, edit, field, allowed
):
    p = _write(tmp_path, GOOD.replace(*edit))
    with pytest.raises(DrugLibraryError) as exc:
        load_library(p)
    msg = str(exc.value)
    assert msg.startswith(f"{p}: field '{field}' = ") and allowed in msg, msg


def test_library_version_and_unreadable_file(tmp_path):
    p = tmp_path / "v.toml"
    p.write_text("format_version = 2\n" + GOOD)
    with pytest.raises(DrugLibraryError, match="field 'format_version' = 2: allowed 1"):
        load_library(p)
    with pytest.raises(DrugLibraryError, match="cannot read"):
        load_library(tmp_path / "none.toml")
    p.write_text("[[")
    with pytest.raises(DrugLibraryError, match="not valid TOML"):
        load_library(p)


def test_limits_round_down_so_the_dose_never_exceeds_the_maximum():
    lib = load_library()
    for c in (16.0, 32.0, 64.0):
        for w in (WEIGHT_MIN_KG, 70.3, 101.7, WEIGHT_MAX_KG):
            lim = lib["norepinephrine"].limits(c, w)
            assert dose_ug_kg_min(lim.hard_max_ml_h, c, w) * w <= 1.0 * w
            assert dose_ug_min(lim.hard_max_ml_h, c) <= 1.0 * w
    with pytest.raises(ValueError, match="need the patient's weight"):
        lib["norepinephrine"].limits(16.0, None)


# -- binding the syringe: design, options, library ------------------------------------------------
def test_bind_syringe_takes_the_design_and_refuses_what_the_library_does_not_allow(tmp_path):
    bound = bind_syringe(ClinicianInput(), DEFAULT_BINDING, "lpv", None)
    assert (bound.drug, bound.concentration_ug_ml, bound.dose_unit) == (
        "phenylephrine",
        100.0,
        "ug/min",
    )
    assert bound.dose_limits.hard_max_ml_h == 120.0
    nor = DrugBinding("norepinephrine", 16.0)
    with pytest.raises(UsageError, match=r"--weight-kg: required: .* norepinephrine in ug/kg/min"):
        bind_syringe(ClinicianInput(), nor, "nor.py", None)
    bound = bind_syringe(ClinicianInput(weight_kg=80.0), nor, "nor.py", None)
    assert bound.dose_limits.hard_max_ml_h == pytest.approx(1.0 * 80 * 60 / 16)
    with pytest.raises(UsageError, match="norepinephrine at 20 ug/ml .* allowed 16, 32, 64"):
        bind_syringe(ClinicianInput(weight_kg=80.0), DrugBinding("norepinephrine", 20.0), "n", None)
    with pytest.raises(UsageError, match="no entry for vasopressin"):
        bind_syringe(ClinicianInput(), DrugBinding("vasopressin", 1.0), "v", None)
    given = ClinicianInput(drug="norepinephrine", drug_given=True)
    with pytest.raises(UsageError, match="--drug norepinephrine: the loaded design .* phenyleph"):
        bind_syringe(given, DEFAULT_BINDING, "lpv", None)
    bad = tmp_path / "bad.toml"
    bad.write_text("format_version = 1\n")
    with pytest.raises(UsageError, match=f"--drug-library {bad}: field 'drugs'"):
        bind_syringe(ClinicianInput(), DEFAULT_BINDING, "lpv", bad)


def test_the_shipped_module_carries_the_binding_of_the_design_toml():
    import pressor.runtime.generated.lpv_map_controller as mod
    from pressor.runtime.inputs.controller_loader import load_controller
    from pressor.synthesis.artifact import default_artifact_path, load_artifact
    from pressor.synthesis.problem.config_toml import default_config_path, load_config

    toml = load_config().drug
    with open(default_config_path(), "rb") as fh:
        assert tomllib.load(fh)["drug"] == toml.to_dict()
    assert load_artifact(default_artifact_path()).drug == toml == DEFAULT_BINDING
    assert (mod.DRUG, mod.DRUG_CONCENTRATION_UG_ML) == (toml.name, toml.concentration_ug_ml)
    assert binding_of(load_controller("lpv", sample_period_s=TS)) == toml
    assert binding_of(load_controller("pi", sample_period_s=TS)) == DEFAULT_BINDING


# -- the supervisor's dose guard ------------------------------------------------------------------
LIMITS = DoseLimits(
    hard_max_ml_h=60.0, soft_max_ml_h=30.0, max_ml_per_hour=40.0, concentration_ug_ml=100.0
)


def _good(now_s: float) -> SupervisorInput:
    return SupervisorInput(
        now_s, 70.0, 0, 0.5, 150.0, 30.0, True, 0.0, 0.0, 80.0, 0, math.nan, 0, False, True, 0
    )


def _supervisor(limits: DoseLimits = LIMITS) -> Supervisor:
    return Supervisor(SupervisorConfig(sample_period_s=TS, dose_limits=limits))


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(allow_nan=True, allow_infinity=True),
            st.floats(min_value=-10.0, max_value=500.0),
            st.none(),
        ),
        min_size=1,
        max_size=80,
    )
)
def test_hard_limit_is_never_exceeded_under_any_controller_output(raws):
    sup = _supervisor()
    for k, raw in enumerate(raws):
        sup.assess(_good(k * TS))
        out = sup.finalize(raw)
        assert 0.0 <= out.command_ml_h <= LIMITS.hard_max_ml_h
        assert dose_ug_min(out.command_ml_h, 100.0) <= 100.0  # 60 ml/h at 100 ug/ml
        if out.command_ml_h > LIMITS.soft_max_ml_h:
            assert out.faults & Fault.DOSE_SOFT_LIMIT and out.alarm


def test_hard_cut_and_soft_alarm_are_advisory_alarms_counted_once_per_episode():
    # doses above the soft maximum confirmed by the clinician: the soft maximum only alarms
    sup = _supervisor(DoseLimits(60.0, 30.0, 1e6, 100.0, confirm_above_soft=True))
    outs = []
    for k, raw in enumerate([10.0, 45.0, 45.0, 90.0, 90.0, 10.0]):
        sup.assess(_good(k * TS))
        outs.append(sup.finalize(raw))
    assert [o.command_ml_h for o in outs] == [10.0, 45.0, 45.0, 60.0, 60.0, 10.0]
    assert [bool(o.faults & DOSE_SOFT_LIMIT) for o in outs] == [0, 1, 1, 1, 1, 0]
    assert [bool(o.faults & DOSE_HARD_LIMIT) for o in outs] == [0, 0, 0, 1, 1, 0]
    assert [o.alarm for o in outs] == [False, True, True, True, True, False]
    assert all(o.state == State.AUTO for o in outs)
    assert sup.detections == {"DOSE_SOFT_LIMIT": 1, "DOSE_HARD_LIMIT": 1}


def test_hourly_maximum_over_a_sliding_hour_tapers_instead_of_a_cliff():
    # 40 ml per hour at most; commanding 60 ml/h approaches it over the taper (10 min), then the
    # command settles on what the room sustains until the old doses leave; the hour's volume never
    # exceeds 40 ml, and the command never falls from full rate to 0 from one tick to the next
    guard = DoseGuard(replace(LIMITS, confirm_above_soft=True), 1.0)
    volumes, cmds, faults = [], [], 0
    for _ in range(3 * 3600):
        cmd, f = guard.limit(60.0)
        faults |= f
        volumes.append(cmd / 3600.0)
        cmds.append(cmd)
        assert math.fsum(volumes[-3600:]) <= 40.0 * (1 + 1e-9)
    assert faults & DOSE_HOUR_LIMIT and faults & DOSE_HARD_LIMIT == 0
    assert 39.0 <= math.fsum(volumes[-3600:]) <= 40.0 * (1 + 1e-9)
    assert max(cmds) == 60.0
    # no cliff: no fall of more than 1 ml/h in a second (it rises as soon as the hour allows)
    assert max(a - b for a, b in zip(cmds, cmds[1:], strict=False)) < 1.0


def test_the_hourly_maximum_charges_elapsed_time_not_ticks():
    # a loop that stalls 10 min between two calls still pays for the 10 min the pump ran
    guard = DoseGuard(replace(LIMITS, confirm_above_soft=True), 0.1)
    guard.limit(30.0, now_s=0.0)
    guard.limit(30.0, now_s=600.0)
    assert guard.hour_volume_ml == pytest.approx(30.0 * 600.0 / 3600.0)


def test_the_soft_maximum_caps_the_command_until_the_clinician_confirms():
    sup = _supervisor(DoseLimits(60.0, 30.0, 1e6, 100.0))
    sup.assess(_good(0.0))
    out = sup.finalize(55.0)
    assert out.command_ml_h == 30.0 and out.faults & DOSE_SOFT_LIMIT and out.alarm
    assert "soft maximum 30 ml/h" in sup.dose_guard.reason


def test_a_cut_that_keeps_the_patient_below_target_for_10_min_is_a_named_shortfall():
    guard = DoseGuard(DoseLimits(60.0, 60.0, 1e6, 100.0), 0.1)
    faults = [guard.limit(90.0, now_s=k * 0.1, short_mmhg=12.0)[1] for k in range(6001)]
    assert not faults[5999] & DOSE_SHORTFALL and faults[6000] & DOSE_SHORTFALL
    assert "hard maximum 60 ml/h" in guard.reason and "12.0 mmHg below the target" in guard.reason


def test_the_pump_maximum_below_every_dose_limit_is_a_named_shortfall_too():
    # a dilute syringe: the library allows 500 ml/h, the pump gives 120; a patient 10 mmHg short
    # at the pump's maximum for 10 min is told so as a dose limit's shortfall would be
    sup = _supervisor(DoseLimits(500.0, 500.0, 1e6, 16.0))
    high = sup.config.max_rate_ml_h
    faults = []
    for k in range(int(600.0 / TS) + 2):
        sup.assess(_good(k * TS))
        faults.append(sup.finalize(2.0 * high).faults)
    assert not faults[0] & DOSE_SHORTFALL and faults[-1] & DOSE_SHORTFALL
    assert f"held at the pump's maximum {high:g} ml/h" in sup.dose_guard.reason
    assert "10.0 mmHg below the target" in sup.dose_guard.reason
    assert "within the pump's maximum" in sup.dose_guard.reason
    # below the pump's maximum nothing holds the dose: no shortfall however long MAP is short
    sup = _supervisor(DoseLimits(500.0, 500.0, 1e6, 16.0))
    for k in range(int(700.0 / TS)):
        sup.assess(_good(k * TS))
        assert not sup.finalize(0.5 * high).faults & DOSE_SHORTFALL


def test_dose_summary_reports_the_unit_limits_and_peak():
    c = bind_syringe(ClinicianInput(weight_kg=80.0), DEFAULT_BINDING, "lpv", None)
    d = dose_summary([0.0, 30.0, 120.0, math.nan], TS, c, {"DOSE_SOFT_LIMIT": 2, "MAP_NAN": 1})
    assert d["unit"] == "ug/min" and d["hard_max"] == pytest.approx(200.0)
    assert d["max_command_ug_min"] == pytest.approx(200.0)
    assert d["max_command_ug_kg_min"] == pytest.approx(2.5)
    assert d["total_ug"] == pytest.approx(150.0 * TS / 3600 * 100.0)
    assert d["detections"] == {"DOSE_SOFT_LIMIT": 2}


def test_library_path_is_package_data():
    assert default_library_path().is_file()
    assert WEIGHT_MIN_KG < 70.0 < WEIGHT_MAX_KG


@pytest.mark.parametrize(
    ("drug", "field"),
    [
        ({"name": "Phenylephrine"}, "drug.name"),
        ({"concentration_ug_ml": 0.0}, "drug.concentration_ug_ml"),
        ({"concentration_ug_ml": "100"}, "drug.concentration_ug_ml"),
        ({"syringe": 1}, "drug.syringe"),
    ],
)
def test_design_toml_drug_section_is_checked_naming_the_field(drug, field):
    from pressor.synthesis.problem.config import ConfigError
    from pressor.synthesis.problem.config_toml import parse_config

    with pytest.raises(ConfigError, match=f"field '{field}'"):
        parse_config({"drug": drug}, source="d.toml")
    assert parse_config({"drug": {"name": "norepinephrine", "concentration_ug_ml": 16}}).drug == (
        DrugBinding("norepinephrine", 16.0)
    )


def test_artifact_metadata_drug_is_checked_and_absent_reads_as_the_default():
    from pressor.synthesis.artifact import ArtifactError, drug_of, make_artifact

    assert drug_of({}) == drug_of({"design": {}}) == DEFAULT_BINDING
    assert drug_of({"design": {"drug": {"name": "x", "concentration_ug_ml": 2.0}}}).name == "x"
    from pressor.synthesis.artifact import default_artifact_path, load_artifact

    art = load_artifact(default_artifact_path())
    meta = {**art.metadata, "design": {**art.metadata["design"], "drug": {"name": ""}}}
    with pytest.raises(ArtifactError, match="metadata.design.drug"):
        make_artifact(meta, art.coefficients, art.nodes)


@pytest.mark.parametrize("controller", ["pi", "smith"])
@pytest.mark.parametrize(
    ("drug", "conc", "weight"),
    [
        ("phenylephrine", 100.0, None),
        ("norepinephrine", 16.0, "70"),
        ("norepinephrine", 64.0, "30"),
    ],
)
def test_every_baseline_runs_on_every_library_drug(controller, drug, conc, weight):
    # pressor run --controller pi|smith --drug D --concentration-ug-ml C: bound to the clinician's
    # syringe (checked against the library), and a device announcing it is accepted
    from types import SimpleNamespace

    from pressor.plumbing.usage import UsageParser
    from pressor.runtime.inputs.clinician import add_clinician_options, clinician_input
    from pressor.runtime.inputs.config import add_run_options, run_config
    from pressor.runtime.inputs.dosing import add_dosing_options
    from pressor.runtime.inputs.hello_checks import check_device_hello

    p = UsageParser(prog="pressor run")
    add_run_options(p)
    add_clinician_options(p)
    add_dosing_options(p)
    argv = ["--controller", controller, "--drug", drug, "--concentration-ug-ml", f"{conc:g}"]
    argv += [] if weight is None else ["--weight-kg", weight]
    args = p.parse_args(argv)
    cfg = run_config(args, clinician=clinician_input(args))
    assert (cfg.clinician.drug, cfg.clinician.concentration_ug_ml) == (drug, conc)
    peer = SimpleNamespace(drug=drug, concentration_ug_ml=conc, pump_max_ml_h=120.0)
    check_device_hello(peer, 120.0, cfg.clinician)
    # a drug-bound design is still refused another drug
    if drug != "phenylephrine":
        lpv = p.parse_args(["--controller", "lpv", *argv[2:]])
        with pytest.raises(UsageError, match="loaded design"):
            run_config(lpv, clinician=clinician_input(lpv))


def test_a_dose_design_takes_every_syringe_of_its_drug_the_library_allows():
    from pressor.plumbing.usage import UsageParser
    from pressor.runtime.inputs.clinician import add_clinician_options, clinician_input
    from pressor.runtime.inputs.config import add_run_options, run_config
    from pressor.runtime.inputs.dosing import add_dosing_options

    p = UsageParser(prog="pressor run")
    add_run_options(p)
    add_clinician_options(p)
    add_dosing_options(p)
    base = ["--controller", "lpv:norepinephrine-cautious", "--weight-kg", "70"]
    for conc in (16.0, 32.0, 64.0):
        args = p.parse_args([*base, "--concentration-ug-ml", f"{conc:g}"])
        cfg = run_config(args, clinician=clinician_input(args))
        assert (cfg.clinician.drug, cfg.clinician.concentration_ug_ml) == ("norepinephrine", conc)
    args = p.parse_args(base)  # no syringe given: the design's
    assert run_config(args, clinician=clinician_input(args)).clinician.concentration_ug_ml == 16.0
    args = p.parse_args([*base, "--concentration-ug-ml", "20"])
    with pytest.raises(UsageError, match="allowed 16, 32, 64"):
        run_config(args, clinician=clinician_input(args))
    # a design in ml/h of one syringe still refuses another
    args = p.parse_args(
        ["--controller", "lpv:norepinephrine", *base[2:], "--concentration-ug-ml", "32"]
    )
    with pytest.raises(UsageError, match="count ml/h of that syringe"):
        run_config(args, clinician=clinician_input(args))
