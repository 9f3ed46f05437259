"""The options of ``pressor device``: the parser, its defaults, the range checks and the world
they describe."""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import Any

from pressor.contracts.controller import DESIGN_CONCENTRATION_UG_ML, DESIGN_DRUG
from pressor.hil_sim.patients.patient_model import add_patient_model_option
from pressor.plumbing.usage import UsageError, UsageParser
from pressor.runtime.inputs.clinician import (
    add_target_option,
    argtype,
    parse_concentration,
    parse_drug,
)
from pressor.runtime.shell.placement import parse_cpu

#: default wall-clock timeouts (s)
RETRANSMIT_S = 0.5
LINK_TIMEOUT_S = 10.0
HANDSHAKE_TIMEOUT_S = 30.0


def device_parser(command: str) -> UsageParser:
    """The option parser of ``pressor device`` (defaults and units in every help)."""
    p = UsageParser(
        prog=f"pressor {command}",
        description="Run the simulated patient/pump/monitor device on a serial port.",
    )
    p.add_argument("--port", required=True, help="device path or pyserial URL (e.g. /dev/pts/7)")
    p.add_argument("--scenario", default="paper-tracking", help="scenario name or .toml path")
    p.add_argument("--patient-seed", type=int, default=0, help="patient seed, [0, 2**32)")
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        help="simulated time (s; default: the scenario's duration_s)",
    )
    p.add_argument("--rate", type=float, default=10.0, help="sample rate (Hz)")
    p.add_argument(
        "--realtime", action="store_true", help="run on the wall clock (default: lockstep)"
    )
    p.add_argument(
        "--signing-key",
        default=None,
        help="MAVLink 2 signing key file (32 B / hex); default: the one 'pressor keygen' wrote",
    )
    p.add_argument(
        "--no-signing", action="store_true", help="run the link unsigned (warned; default: signed)"
    )
    p.add_argument(
        "--tlog", default=None, help="write every link frame to this .tlog (default: none)"
    )
    p.add_argument(
        "--retransmit",
        type=float,
        default=RETRANSMIT_S,
        help="wall-clock s without a command before resending a tick (s)",
    )
    p.add_argument(
        "--link-timeout",
        type=float,
        default=LINK_TIMEOUT_S,
        help="wall-clock s without a command before giving up (s)",
    )
    p.add_argument(
        "--handshake-timeout",
        type=float,
        default=HANDSHAKE_TIMEOUT_S,
        help="wall-clock s to wait for the runtime's hello (s)",
    )
    p.add_argument(
        "--cpu",
        type=parse_cpu,
        default=None,
        help="run on this CPU only (default: any; pressor sil puts the lockstep ends on two CPUs)",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="KIND[:ARGS]",
        help="inject a fault (repeatable); 'pressor faults' lists kinds, arguments and defaults",
    )
    p.add_argument(
        "--drug",
        type=argtype("--drug", parse_drug),
        default=DESIGN_DRUG,
        help=f"drug in the syringe, announced in the hello (default: {DESIGN_DRUG})",
    )
    p.add_argument(
        "--concentration-ug-ml",
        type=argtype("--concentration-ug-ml", parse_concentration),
        default=DESIGN_CONCENTRATION_UG_ML,
        metavar="UG_ML",
        help="syringe concentration announced in the hello (ug/ml, default"
        f" {DESIGN_CONCENTRATION_UG_ML:g}: the one the simulated patient's K assumes)",
    )
    p.add_argument(
        "--pump-max-ml-h",
        type=float,
        default=None,
        metavar="ML_H",
        help="the pump's largest rate (ml/h, (0, 10000]), announced in the hello (default: the"
        " scenario's [pump] max_rate_ml_h, 120 ml/h in every shipped scenario)",
    )
    p.add_argument(
        "--truth-out",
        default=None,
        metavar="FILE.npz",
        help="write the simulated patient's true MAP per tick (mmHg) to FILE.npz when the device"
        " ends (default: none; pressor sil adds it to its recording)",
    )
    add_target_option(
        p,
        "an absolute MAP target (mmHg, {rng}) sent as MAP_TARGET from the scenario's step time on,"
        " in place of the scenario's step above the patient's baseline (default: the scenario's"
        " step)",
    )
    add_patient_model_option(p)
    return p


def make_world(args: argparse.Namespace, faults: tuple = ()) -> Any:
    """The :class:`pressor.hil_sim.world.World` of the parsed options: ``--scenario``, ``--patient-seed``,
    ``--rate`` (Hz), ``--patient-model``, the pump's maximum replaced by ``--pump-max-ml-h``
    (ml/h) and the target by ``--target-mmhg`` (mmHg, absolute) if given; ``faults`` injected. Bad input raises :class:`UsageError` naming the option."""
    from pressor.hil_sim.patients.patient_model import PatientModelError
    from pressor.hil_sim.scenarios.scenario import ScenarioError, load_scenario
    from pressor.hil_sim.world import World

    try:
        sc = load_scenario(args.scenario)
    except ScenarioError as exc:
        raise UsageError(str(exc)) from exc
    if args.pump_max_ml_h is not None:
        try:
            sc = replace(sc, pump=replace(sc.pump, max_rate_ml_h=args.pump_max_ml_h))
        except ValueError as exc:  # e.g. the scenario's safe rate above the new maximum
            raise UsageError(f"--pump-max-ml-h {args.pump_max_ml_h:g}: {exc}") from exc
    if getattr(args, "target_mmhg", None) is not None:
        sc = replace(sc, target_mmhg=args.target_mmhg)
    try:
        return World(sc, args.patient_seed, 1.0 / args.rate, faults, args.patient_model)
    except PatientModelError as exc:
        raise UsageError(str(exc)) from exc
    except ValueError as exc:
        raise UsageError(f"--rate: {exc}") from exc
