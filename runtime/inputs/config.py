"""The runtime's typed run configuration, parsed and checked at the command line.

``pressor run`` and ``pressor sil`` share the runtime's options
(:func:`pressor.runtime.inputs.run_options.add_run_options`); the
parsed namespace becomes a frozen :class:`RunConfig` in :func:`run_config`, which checks every
value before anything starts (output directories, the controller, the fault specs). A bad value
raises :class:`pressor.plumbing.usage.UsageError` naming the option, the value and the allowed range;
past this boundary the run code trusts its configuration.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pressor.contracts.drug import DrugBinding
from pressor.contracts.faults import FaultSpec, FaultSpecError, parse_faults
from pressor.plumbing.usage import UsageError
from pressor.runtime.core.supervisor_config import DEFAULT_SAMPLE_AGE_LIMIT_S
from pressor.runtime.inputs.clinician import ClinicianInput
from pressor.runtime.inputs.run_options import (
    CONTROLLER_DEFAULT_HELP,
    DEFAULT_RATE_HZ,
    MAX_RATE_HZ,
    SCHEDULE_DEFAULT_HELP,
    SCHEDULE_HELP,
    STOP_COMMANDS,
    add_run_options,
    positive,
)
from pressor.runtime.shell.viewer import DEFAULT_VIEW_PORT

__all__ = [  # the options are run_options'; importers of the shared names find them here too
    "CONTROLLER_DEFAULT_HELP",
    "DEFAULT_RATE_HZ",
    "MAX_RATE_HZ",
    "SCHEDULE_DEFAULT_HELP",
    "SCHEDULE_HELP",
    "STOP_COMMANDS",
    "RunConfig",
    "add_run_options",
    "load_controller",
    "load_signing",
    "positive",
    "resolve_controller",
    "run_config",
]


@dataclass(frozen=True)
class RunConfig:
    """One runtime run, as the command line asked for it (checked by :func:`run_config`).

    Attributes
    ----------
    controller
        The ``--controller`` spec (``lpv``, ``pi``, ``smith[:LAMBDA_S]``, a generated module or a
        plugin, :mod:`pressor.runtime.inputs.controller_plugin`).
    rate_hz
        Loop rate (Hz).
    realtime
        Wall clock instead of lockstep.
    rrd, tlog, summary, timing
        Output files (``None``: not written); their directories exist.
    signing_key
        Key file of the signed link (``None``: none given).
    signed
        ``False`` with ``--no-signing``.
    sched_faults
        ``advise`` or ``hold``: the supervisor's answer to scheduling outside the design box.
    faults
        The ``--fault`` texts as given (a device process gets them verbatim).
    fault_specs
        The faults to score after the run: the parsed ``--fault`` texts, then any the device's
        scenario declares.
    stall_timeout_s
        Lockstep: wall seconds without a sample before giving up.
    cpu_latency_us
        CPU wake-up latency to hold during the run (µs; ``None``: no request).
    ticks
        Ticks to run (0: until the device ends).
    schedule
        The scheduling source (``oracle``, ``estimated``, ``nominal``, ``validated``;
        :func:`pressor.runtime.estimation.sources.make_schedule`).
    clinician
        ``pressor run``'s target and syringe options (:mod:`pressor.runtime.inputs.clinician`); ``None``
        (``pressor sil``): the device's target, the shipped designs' drug and concentration.
    sample_age_limit_s
        Age (s) past which the held MAP sample is stale (the supervisor's ``STALE_SAMPLE``).
    on_stop
        The last command a stop signal sends (``--on-stop``): ``held`` (the safe rate, else the
        last rate held, mode SAFE) or ``zero`` (0 ml/h, mode STOP).
    status_every_s
        Wall seconds between two status lines on stderr (``--status-every``;
        :mod:`pressor.runtime.shell.status`), None with ``--quiet``.
    syringe
        ``pressor sil`` with a drug-agnostic baseline (PI, Smith): the drug and syringe the
        simulated device announces (the patient model's), which the runtime end binds it to;
        None: the loaded design's (:func:`pressor.contracts.drug.binding_of`).
    view, view_port
        ``--view``: stream the run to a rerun viewer listening on 127.0.0.1:``view_port``
        (:mod:`pressor.runtime.shell.viewer`).
    clinician_stdin
        ``pressor sil --clinician-stdin``: the clinician's ``ack``, ``stop``, ``manual RATE`` and
        ``resume`` on stdin, the target staying the device's (``pressor run`` has them on its
        target inputs).
    """

    controller: str
    rate_hz: float
    realtime: bool
    rrd: Path | None
    tlog: Path | None
    summary: Path | None
    timing: Path | None
    signing_key: Path | None
    sched_faults: str
    faults: tuple[str, ...]
    fault_specs: tuple[FaultSpec, ...]
    stall_timeout_s: float
    cpu_latency_us: int | None
    ticks: int = 0
    schedule: str = "oracle"
    signed: bool = True
    clinician: ClinicianInput | None = None
    sample_age_limit_s: float = DEFAULT_SAMPLE_AGE_LIMIT_S
    on_stop: str = "held"
    status_every_s: float | None = None
    clinician_stdin: bool = False
    syringe: DrugBinding | None = None
    view: bool = False
    view_port: int = DEFAULT_VIEW_PORT

    @property
    def period_s(self) -> float:
        """The sample period (s)."""
        return 1.0 / self.rate_hz

    @property
    def mode(self) -> str:
        """``realtime`` or ``lockstep``."""
        return "realtime" if self.realtime else "lockstep"


def resolve_controller(args: argparse.Namespace) -> None:
    """Set ``args.controller`` to the default when none was given: the design of the drug named
    by ``--drug`` (``pressor run``), else of the default drug
    (:func:`pressor.runtime.inputs.defaults.default_controller`)."""
    if args.controller is None:
        from pressor.runtime.inputs.defaults import default_controller

        args.controller = default_controller(getattr(args, "drug", None))


def run_config(
    args: argparse.Namespace, ticks: int = 0, clinician: ClinicianInput | None = None
) -> RunConfig:
    """Check the options :func:`add_run_options` parsed and freeze them into a :class:`RunConfig`.

    Parameters
    ----------
    args
        The parsed namespace.
    ticks
        ``pressor run --ticks`` (0: until the device ends).
    clinician
        ``pressor run``'s checked target and syringe options
        (:func:`pressor.runtime.inputs.clinician.clinician_input`); checked against the loaded design and
        the drug library (:func:`pressor.runtime.inputs.dosing.bind_syringe`).

    Raises
    ------
    pressor.plumbing.usage.UsageError
        A value out of range, an output directory that does not exist, a controller that does
        not load, a bad fault spec.
    """
    if ticks < 0:
        raise UsageError(f"--ticks {ticks}: allowed >= 0")
    _check_out_path("--rrd", args.rrd, ".rrd")
    _check_out_path("--tlog", args.tlog)
    _check_out_path("--summary", args.summary)
    _check_out_path("--timing", args.timing)
    if args.no_signing and args.signing_key is not None:
        raise UsageError("--no-signing and --signing-key: choose one")
    if args.sample_age_limit_s < 1.0 / args.rate:
        raise UsageError(
            f"--sample-age-limit-s {args.sample_age_limit_s:g}: allowed [1/--rate ="
            f" {1.0 / args.rate:g}, 60] s"
        )
    resolve_controller(args)
    controller = load_controller(args.controller, 1.0 / args.rate)  # fail fast, before a device
    if args.schedule is None:
        from pressor.runtime.inputs.defaults import default_schedule

        args.schedule = default_schedule(controller)
    if clinician is not None:  # pressor run: the syringe and patient against design and library
        from pressor.contracts.drug import DrugBinding, binding_of, dose_scaled, drug_agnostic
        from pressor.runtime.inputs.dosing import bind_syringe

        try:
            if drug_agnostic(controller):  # a baseline: the clinician's drug and syringe
                design = DrugBinding(clinician.drug, clinician.concentration_ug_ml)
            else:
                design = binding_of(controller)
                if dose_scaled(controller) and clinician.concentration_given:
                    # sized in doses: any syringe of its drug the library allows
                    design = DrugBinding(design.name, clinician.concentration_ug_ml)
        except ValueError as exc:
            raise UsageError(f"--controller {args.controller}: {exc}") from None
        clinician = bind_syringe(
            clinician,
            design,
            args.controller,
            args.drug_library,
            getattr(args, "confirm_above_soft_limit", False),
        )
    try:
        specs = tuple(parse_faults(args.fault))
    except FaultSpecError as exc:
        raise UsageError(str(exc)) from None
    return RunConfig(
        controller=args.controller,
        rate_hz=args.rate,
        realtime=args.realtime,
        rrd=args.rrd,
        tlog=args.tlog,
        summary=args.summary,
        timing=args.timing,
        signing_key=args.signing_key,
        sched_faults=args.sched_faults,
        faults=tuple(args.fault),
        fault_specs=specs,
        stall_timeout_s=args.stall_timeout,
        cpu_latency_us=args.cpu_latency,
        ticks=ticks,
        schedule=args.schedule,
        signed=not args.no_signing,
        clinician=clinician,
        sample_age_limit_s=args.sample_age_limit_s,
        on_stop=args.on_stop,
        status_every_s=None if args.quiet else args.status_every,
        view=args.view,
        view_port=args.view_port,
    )


def _check_out_path(opt: str, path: Path | None, suffix: str | None = None) -> None:
    if path is None:
        return
    if suffix and path.suffix != suffix:
        raise UsageError(f"{opt} {path}: expected a {suffix} file name")
    if not path.parent.resolve().is_dir():
        raise UsageError(f"{opt} {path}: directory {path.parent} does not exist")


def load_controller(spec: str, period_s: float) -> Any:
    """The controller ``spec`` names at ``period_s`` (s); a :class:`UsageError` if it does not load."""
    from pressor.runtime.inputs.controller_loader import ControllerSpecError
    from pressor.runtime.inputs.controller_loader import load_controller as load

    try:
        return load(spec, sample_period_s=period_s)
    except ControllerSpecError as exc:
        hint = ""
        if spec == "lpv":
            hint = (
                " (the shipped LPV module is generated by 'pressor codegen --target python"
                " --out runtime/generated'; use --controller pi meanwhile)"
            )
        raise UsageError(f"--controller {spec}: {exc}{hint}") from None


def warn_uncautious(spec: str, schedule: str, prog: str) -> str | None:
    """Say on stderr, as ``PROG: warning: ...``, when nothing sizes the first doses of
    ``--controller spec`` on ``--schedule schedule`` for the most sensitive patient
    (:func:`pressor.runtime.inputs.defaults.caution_warning`), and return the line (for a run's
    summary and recording); None, and nothing said, otherwise."""
    from pressor.runtime.inputs.defaults import caution_warning

    line = caution_warning(spec, schedule)
    if line is not None:
        print(f"{prog}: warning: {line}", file=sys.stderr)
    return line


def load_signing(
    config: RunConfig,
    generate: bool,
    prog: str = "pressor run",
    warnings: list[str] | None = None,
) -> Any:
    """The link's :class:`Signing`, or ``None`` with ``--no-signing``.

    From ``--signing-key``; else a fresh key if ``generate`` (``pressor sil``); else the key file
    at :func:`pressor.link.signing.default_key_path` (``pressor run``). A key file that is missing or
    cannot be read is a :class:`UsageError` saying how to make one. Called before any port opens.
    A key file readable by every user or a key of all zeros
    (:func:`pressor.link.signing.key_file_warnings`) is one line ``PROG: warning: ...`` each on
    stderr, also appended to ``warnings`` (for the run's summary) when given.
    """
    from pressor.link.signing import Signing, default_key_path, key_file_warnings

    if not config.signed:
        return None
    path = config.signing_key
    if path is None:
        if generate:
            return Signing.generate()
        path = default_key_path()
        if not path.exists():
            raise UsageError(
                f"--signing-key: no key at the default {path}: make one with 'pressor keygen'"
                " (the device needs the same file), or pass --no-signing"
            )
    try:
        signing = Signing.from_file(path)
    except OSError as exc:
        raise UsageError(f"--signing-key {path}: cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:  # its text names the file
        raise UsageError(f"--signing-key {exc}") from None
    for line in key_file_warnings(path, signing.key):
        print(f"{prog}: warning: {line}", file=sys.stderr)
        if warnings is not None:
            warnings.append(line)
    return signing
