"""``pressor sil``: the software-in-the-loop run, device process and runtime over a serial link.

The front door knows both ends, so the two-process orchestration lives here: ``pressor sil``
loads the scenario through the simulator's scenario API (:mod:`pressor.hil_sim.scenarios.scenario`), starts the
device as its own process (``python -m pressor device --port ...``), connects to it over a
pseudo-terminal (a real tty to pyserial), signs the link (a fresh key per run unless
``--signing-key``), runs the runtime in lockstep (or ``--realtime``) through
:func:`pressor.runtime.session.run_runtime`, records everything to an ``.rrd``, prints the metric summary
(:mod:`pressor.runtime.summary`, defined in docs/METRICS.md) and the ``rerun FILE.rrd`` command to replay
it. The run lasts the scenario's ``duration_s`` unless ``--duration`` is given; on a terminal a
status line shows simulated time and the real-time factor (:mod:`pressor.runtime.shell.progress`). The
runtime itself never imports the simulator: the control path learns of the patient, and of any
fault, only through what arrives on the link. ``--schedule`` picks where the controller's K, T, τ
come from (:func:`pressor.runtime.estimation.sources.make_schedule`); the controller, the schedule and
the scenario default to what ``pressor run`` and ``pressor trial`` default to
(:mod:`pressor.runtime.inputs.defaults`). ``--patient-model`` picks the device's patient model
(:mod:`pressor.hil_sim.patients.patient_model`); a model other than ``paper`` is named in the summary as
``patient_model``.

Faults. ``--fault KIND[:ARGS]`` (repeatable) is passed to the device process, which injects it.
Faults the scenario declares (``[[faults]]``) are injected by the device too; both are scored
after the run (summary ``faults`` list, docs/METRICS.md). The scenario's hemorrhages and boluses
are the disturbance events the metrics split the run at.

Files. The ``.tlog`` is written in place, the ``.rrd``, ``--summary`` and ``--timing`` files to a
hidden temporary name renamed when written; a run that fails keeps its ``.tlog``, ``.rrd`` and
summary (:mod:`pressor.runtime.session`). The signing key reaches the device process through a pipe it
inherits (``--signing-key /dev/fd/N``), never through a file.

Exit codes: 0 success, 1 the run completed but a check failed (or the device stalled, or the link
failed), 2 bad usage or input (one line on stderr naming the option or file, value and range).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from pressor.contracts.checks import check_int_range
from pressor.contracts.drug import DEFAULT_BINDING, DrugBinding
from pressor.hil_sim.patients.patient_model import add_patient_model_option
from pressor.plumbing.usage import USAGE_EXIT, UsageError, UsageParser, parse_first
from pressor.runtime.inputs.clinician import add_syringe_options, add_target_option
from pressor.runtime.inputs.config import (
    RunConfig,
    add_run_options,
    positive,
    run_config,
)
from pressor.runtime.inputs.defaults import DEFAULT_SCENARIO
from pressor.runtime.inputs.dosing import add_weight_option
from pressor.runtime.shell.placement import CpuChoice, parse_lockstep_cpus

#: what the clinical options mean for ``pressor sil``
SIL_TARGET_HELP = (
    "an absolute MAP target (mmHg, {rng}) the simulated device sends from the scenario's step"
    " time on, in place of the scenario's step above the patient's baseline (default: the"
    " scenario's step)"
)
SIL_DRUG_HELP = (
    "drug in the syringe, which the simulated device announces: must be the loaded design's, and"
    " the design must be for the patient model's drug (default: the design's)"
)
SIL_CONCENTRATION_HELP = (
    "syringe concentration (ug/ml) the simulated device announces: must be the one whose ml/h"
    " the design counts (default: the design's)"
)
SIL_WEIGHT_HELP = (
    "the patient's weight (kg, {rng}): the summary's doses in ug/kg/min are per this weight"
    " (default: a 70 kg reference adult, said so)"
)
DEFAULT_PATIENT_SEED = 1
#: longest simulated run (s)
MAX_DURATION_S = 7 * 86400.0


@dataclass(frozen=True)
class SilConfig:
    """One ``pressor sil`` run, checked at the command line (:func:`sil_config`).

    Attributes
    ----------
    run
        The runtime end's configuration; its ``fault_specs`` include the scenario's faults.
    scenario
        Scenario name, or the absolute path of a scenario file, as passed to the device.
    patient_seed
        The device's patient seed.
    duration_s
        Simulated time (s).
    link
        ``pty`` (the only transport ``pressor sil`` creates).
    signed
        Whether the link is signed (``--no-signing`` turns a generated key off).
    cpu
        Lockstep CPU placement choice (:mod:`pressor.runtime.shell.placement`).
    events
        The scenario's disturbance events ``(kind, start_s)`` for the metrics.
    noisy
        Whether the scenario's monitor adds noise (the metrics' settling band, docs/METRICS.md).
    patient_model
        The device's patient model (a :data:`pressor.hil_sim.patients.patient_model.PATIENT_MODELS` name or
        ``MODULE:CLASS``).
    drug
        The loaded design's drug and syringe (:func:`pressor.contracts.drug.binding_of`): the device is
        told to announce them (``--drug``, ``--concentration-ug-ml``).
    target_mmhg
        ``--target-mmhg``: an absolute target (mmHg) the device sends in place of the scenario's
        step; ``None``: the scenario's step.
    weight_kg
        ``--weight-kg``: the patient's weight (kg) the summary's doses per kg are for; ``None``:
        the 70 kg reference adult.
    """

    run: RunConfig
    scenario: str
    patient_seed: int
    duration_s: float
    link: str
    signed: bool
    cpu: CpuChoice
    events: tuple[tuple[str, float], ...]
    noisy: bool
    patient_model: str = "paper"
    drug: DrugBinding = DEFAULT_BINDING
    target_mmhg: float | None = None
    weight_kg: float | None = None


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--patient-seed {text!r}: not an integer") from None
    return check_int_range("--patient-seed", value, 0, 2**32 - 1, error=argparse.ArgumentTypeError)


def sil_parser() -> UsageParser:
    """The ``pressor sil`` option parser: the runtime's options plus the device's."""
    p = UsageParser(prog="pressor sil", description="device process + runtime over a serial link")
    add_run_options(p)
    p.add_argument(
        "--scenario",
        default=DEFAULT_SCENARIO,
        help="scenario name ('pressor scenarios' lists them) or a .toml path",
    )
    p.add_argument(
        "--patient-seed",
        type=_seed,
        default=DEFAULT_PATIENT_SEED,
        help="seed of the simulated patient, [0, 2**32)",
    )
    p.add_argument(
        "--duration",
        type=positive("--duration", MAX_DURATION_S),
        default=None,
        help="simulated time in s (default: the scenario's duration_s)",
    )
    p.add_argument("--link", default="pty", help="pty (default) or a pyserial URL / device path")
    p.add_argument(
        "--cpu",
        type=parse_lockstep_cpus,
        default="auto",
        metavar="auto|none|N|N,M",
        help="lockstep CPU placement: auto (default) the loop thread on the CPU it is on and the"
        " device on another; N both on CPU N; N,M the loop on N and the device on M; none let"
        " the scheduler place them. Ignored with --realtime",
    )
    p.add_argument(
        "--clinician-stdin",
        action="store_true",
        help="the clinician's lines on stdin while running: 'stop' (0 ml/h now, held), 'manual"
        " RATE' (ml/h, held), 'resume' (back to automatic control), 'ack' (acknowledge an"
        " alarm); the target stays the device's, the scenario's or --target-mmhg (default: off)",
    )
    add_patient_model_option(p)
    add_target_option(p, SIL_TARGET_HELP)
    add_syringe_options(p, SIL_DRUG_HELP, SIL_CONCENTRATION_HELP)
    add_weight_option(p, SIL_WEIGHT_HELP)
    return p


def sil_config(argv: Sequence[str]) -> SilConfig:
    """Parse and check ``pressor sil`` arguments; the scenario is loaded to read its faults and
    disturbance events (raises :class:`pressor.plumbing.usage.UsageError`)."""
    from pressor.contracts.drug import binding_of, drug_agnostic
    from pressor.hil_sim.patients.patient_model import (
        PatientModelError,
        check_model_for_scenario,
        default_design,
        model_drug,
    )
    from pressor.hil_sim.patients.syringe import check_drug
    from pressor.hil_sim.scenarios.scenario import ScenarioError, is_scenario_path, load_scenario
    from pressor.hil_sim.trials.trial import scenario_events
    from pressor.runtime.inputs.config import load_controller

    args = sil_parser().parse_args(argv)
    if args.controller is None:  # the design for the simulated patient's drug
        try:
            args.controller = default_design(args.patient_model)
        except PatientModelError as exc:
            raise UsageError(str(exc)) from None
    if args.rrd is None:
        args.rrd = Path(
            f"pressor_sil_{_file_label(args.controller)}_{Path(args.scenario).stem}"
            f"_seed{args.patient_seed}.rrd"
        )
    run = replace(run_config(args), clinician_stdin=args.clinician_stdin)
    controller = load_controller(args.controller, 1.0 / args.rate)
    try:
        drug = binding_of(controller)
        if drug_agnostic(controller):  # a baseline runs on the simulated patient's drug
            drug = model_drug(args.patient_model) or drug
            run = replace(run, syringe=drug)
    except (ValueError, PatientModelError) as exc:
        raise UsageError(f"--controller {args.controller}: {exc}") from None
    try:
        scenario = load_scenario(args.scenario)
        check_model_for_scenario(args.patient_model, scenario.name, scenario.frozen is not None)
        # a design meets only its drug; the syringe given is the design's (pressor run's rule)
        check_drug(controller, args.controller, args.patient_model)
    except (ScenarioError, PatientModelError) as exc:
        raise UsageError(str(exc)) from None
    _check_syringe(args, drug)
    if args.link != "pty":
        raise UsageError(
            f"--link {args.link}: pressor sil starts the device on a pty it creates; for a device"
            " on another port run 'pressor device --port ...' there and 'pressor run --port"
            f" {args.link}' here"
        )
    return SilConfig(
        run=replace(run, fault_specs=run.fault_specs + scenario.faults),
        scenario=str(Path(args.scenario).resolve())  # the device may start elsewhere
        if is_scenario_path(args.scenario)
        else args.scenario,
        patient_seed=args.patient_seed,
        duration_s=scenario.duration_s if args.duration is None else args.duration,
        link=args.link,
        signed=run.signed,
        cpu=args.cpu,
        events=tuple(scenario_events(scenario)),
        noisy=scenario.noisy,
        patient_model=args.patient_model,
        drug=drug,
        target_mmhg=args.target_mmhg,
        weight_kg=args.weight_kg,
    )


def _check_syringe(args: argparse.Namespace, drug: DrugBinding) -> None:
    """Refuse a ``--drug`` or ``--concentration-ug-ml`` that is not the syringe the runtime end
    binds the loaded controller to (``drug``; a drug-agnostic baseline: the shipped designs'),
    naming both, as ``pressor run`` refuses one that is not the design's."""
    import math

    where = f"the loaded controller (--controller {args.controller}) runs on {drug.describe()}"
    if args.drug is not None and args.drug != drug.name:
        raise UsageError(f"--drug {args.drug}: {where}")
    conc = args.concentration_ug_ml
    if conc is not None and not math.isclose(conc, drug.concentration_ug_ml, rel_tol=1e-6):
        raise UsageError(f"--concentration-ug-ml {conc:g}: {where}")


def _file_label(spec: str) -> str:
    """The controller's part of the default ``.rrd`` name (a plugin: its class name)."""
    from pressor.runtime.inputs.controller_plugin import is_plugin_spec, plugin_label

    if spec.partition(":")[0] == "lpv":  # lpv:NAME, a shipped design
        return spec.replace(":", "_")
    return plugin_label(spec) if is_plugin_spec(spec) else Path(spec).stem


def device_command(
    config: SilConfig,
    port_path: str,
    cpu: int | None,
    key_file: Path | None,
    truth_out: Path | None = None,
) -> list[str]:
    """The ``python -m pressor device`` command line of the device process for ``config``."""
    run = config.run
    cmd = [
        sys.executable,
        "-m",
        "pressor",
        "device",
        "--port",
        port_path,
        "--scenario",
        config.scenario,
        "--patient-seed",
        str(config.patient_seed),
        "--duration",
        repr(config.duration_s),
        "--rate",
        repr(run.rate_hz),
    ]
    if run.realtime:
        cmd.append("--realtime")
    if cpu is not None:
        cmd += ["--cpu", str(cpu)]
    for text in run.faults:
        cmd += ["--fault", text]
    if any(f.info.group == "link" for f in run.fault_specs):
        cmd += ["--retransmit", "0.05"]  # wall-clock resend of lost ticks; trajectory-neutral
    cmd += ["--signing-key", str(key_file)] if key_file is not None else ["--no-signing"]
    if truth_out is not None:
        cmd += ["--truth-out", str(truth_out)]
    if config.patient_model != "paper":  # the default's command line is unchanged
        cmd += ["--patient-model", config.patient_model]
    if config.drug != DEFAULT_BINDING:  # the default's command line is unchanged
        cmd += ["--drug", config.drug.name]
        cmd += ["--concentration-ug-ml", repr(config.drug.concentration_ug_ml)]
    if config.target_mmhg is not None:
        cmd += ["--target-mmhg", repr(config.target_mmhg)]
    return cmd


def run_sil(
    config: SilConfig, on_tick: Callable[[int, int, int, float], object] | None = None
) -> tuple[dict[str, Any], Any]:
    """Start the device process on a fresh pty, run the runtime against it; return
    ``(summary, result)`` (:func:`pressor.runtime.session.run_runtime`).

    ``on_tick`` is the loop's per-tick callback ``(tick, state, fault bits, command ml/h)``
    (e.g. ``benchmarks/memory_soak.py``'s memory probe); on a terminal the status line takes
    its place.

    A device that exits with a usage error turns into a :class:`UsageError` with its message;
    any other device output is printed on stderr when the run fails or the device exits non-zero.
    """
    from pressor.link import PtyPair
    from pressor.runtime.core.closed_loop import ControllerError
    from pressor.runtime.inputs.config import load_signing
    from pressor.runtime.session import run_runtime, start_run
    from pressor.runtime.shell.interrupt import Interrupted
    from pressor.runtime.shell.placement import lockstep_cpus
    from pressor.runtime.shell.progress import TerminalProgress

    run = config.run
    key_warnings: list[str] = []  # a --signing-key file every user can read, an all-zero key
    signing = load_signing(run, generate=config.signed, prog="pressor sil", warnings=key_warnings)
    identity = {
        "controller": run.controller,
        "link": config.link,
        "mode": run.mode,
        "rate_hz": run.rate_hz,
        "duration_s": config.duration_s,
        "signed": signing is not None,
    }
    if key_warnings:  # only then: the summaries of other runs keep their bytes
        identity["signing_warnings"] = key_warnings
    if config.patient_model != "paper":  # the default's summaries keep their bytes
        identity["patient_model"] = config.patient_model
    if config.target_mmhg is not None:
        identity["target_mmhg"] = config.target_mmhg
    if config.weight_kg is not None:
        identity["weight_kg"] = config.weight_kg
    cpus = lockstep_cpus(config.cpu, run.realtime)
    start_run()  # from here a stop signal is graceful: the device and the pty are ours to end
    pair = PtyPair.open()
    with tempfile.TemporaryDirectory(prefix="pressor-sil-") as tmp:
        # the key goes to the device through a pipe it inherits (read as /dev/fd/N), never
        # through a file: a killed run leaves no key behind in the temporary folder
        key_fd = _key_pipe(signing) if signing is not None else None
        key_file = None if key_fd is None else Path(f"/dev/fd/{key_fd}")
        truth_file = Path(tmp) / "truth.npz" if run.rrd is not None else None
        cmd = device_command(
            config, pair.follower_path, None if cpus is None else cpus[1], key_file, truth_file
        )
        device_log = Path(tmp) / "device.log"
        try:
            with open(device_log, "wb") as log:
                # its own session: a terminal's Ctrl-C reaches the runtime only, which stops the
                # run (safe rate, outputs kept) and closes the link; the device then ends by itself
                proc = subprocess.Popen(
                    cmd,
                    stdin=subprocess.DEVNULL,  # stdin is the clinician's (--clinician-stdin)
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                    pass_fds=() if key_fd is None else (key_fd,),
                )
        finally:
            if key_fd is not None:
                os.close(key_fd)
        port = pair.leader_port()
        progress = TerminalProgress(run.period_s, round(config.duration_s / run.period_s))
        try:
            summary, result = run_runtime(
                port,
                run,
                identity,
                signing,
                events=list(config.events),
                cpus=cpus,
                on_connected=pair.close_follower,
                peer_alive=lambda: proc.poll() is None,
                on_tick=progress if progress.enabled else on_tick,
                before_close=None
                if truth_file is None
                else lambda rec: _add_truth(rec, proc, truth_file, config.drug, config.weight_kg),
                noisy_band=config.noisy,
            )
        except Interrupted:
            # before the device connected: nothing to keep, one line; the device is told at once
            # (SIGTERM: it stops gracefully, or dies while it still imports) rather than waited
            # for, so that the command ends within a second of the signal
            _stop(proc, grace_s=0.0)
            raise
        except ControllerError:
            _stop(proc)  # the runtime's own fault: the device only saw the link close
            raise
        except Exception:
            _stop(proc)
            text = device_log.read_text(errors="replace").strip()
            if proc.returncode == USAGE_EXIT and text:
                line = text.splitlines()[-1]
                raise UsageError(line.removeprefix("pressor device: ")) from None
            if text:
                print(f"device output:\n{text}", file=sys.stderr)
            raise
        finally:
            progress.close()
            pair.close()
        code = _stop(proc, grace_s=10.0)
        if code not in (0, None):
            text = device_log.read_text(errors="replace").strip()
            print(f"device exited with {code}:\n{text}", file=sys.stderr)
    return summary, result


def _key_pipe(signing: Any) -> int:
    """The read end of a pipe holding ``signing``'s key as 64 hex characters (a key file's
    format), its write end closed: the device process inherits it and reads it once."""
    read_fd, write_fd = os.pipe()
    try:
        os.write(write_fd, (signing.key.hex() + "\n").encode("ascii"))  # < a pipe's buffer
    finally:
        os.close(write_fd)
    return read_fd


def _add_truth(
    recorder: Any,
    proc: subprocess.Popen,
    truth_file: Path,
    drug: DrugBinding = DEFAULT_BINDING,
    weight_kg: float | None = None,
) -> None:
    """Add the device's true MAP, and the dose its pump delivered in µg/min and µg/kg/min (of
    ``drug``'s syringe, per ``weight_kg`` or the 70 kg reference adult), to the recording once the
    device has ended and written them (``pressor device --truth-out``); a device that did not
    write them leaves the series out."""
    from pressor.contracts.drug import REFERENCE_WEIGHT_KG
    from pressor.hil_sim.patients.truth import load_truth, load_truth_rate
    from pressor.runtime.record.blueprint import DELIVERED_DOSE_ENTITIES

    try:
        proc.wait(timeout=10.0)
    except subprocess.TimeoutExpired:
        return  # _stop ends it; the recording goes without the true MAP
    if truth_file.is_file():
        ticks, times_s, map_true = load_truth(truth_file)
        recorder.log_series("/patient/map_true_mmhg", "MAP true (mmHg)", ticks, times_s, map_true)
        rate = load_truth_rate(truth_file)
        if rate is not None:
            c = drug.concentration_ug_ml
            w = REFERENCE_WEIGHT_KG if weight_kg is None else weight_kg
            per = f"{w:g} kg" if weight_kg is not None else f"{w:g} kg reference"
            per_min, per_kg = DELIVERED_DOSE_ENTITIES
            label = f"{drug.name} {c:g} ug/ml"
            recorder.log_series(
                per_min, f"dose delivered (ug/min, {label})", ticks, times_s, rate * c / 60.0
            )
            recorder.log_series(
                per_kg,
                f"dose delivered (ug/kg/min, {per})",
                ticks,
                times_s,
                rate * c / (60.0 * w),
            )


def _stop(proc: subprocess.Popen, grace_s: float = 2.0) -> int | None:
    """Wait for our device process; terminate it (by its pid) if it does not exit in time
    (``grace_s`` 0: at once)."""
    try:
        return proc.wait(timeout=grace_s) if grace_s > 0 else _still_running(proc)
    except subprocess.TimeoutExpired:
        proc.terminate()
        try:
            return proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait()


def _still_running(proc: subprocess.Popen) -> int:
    """``proc``'s exit code if it has exited; else raise :class:`subprocess.TimeoutExpired`."""
    code = proc.poll()
    if code is None:
        raise subprocess.TimeoutExpired(proc.args, 0.0)
    return code


def _main(argv: Sequence[str]) -> int:
    from pressor.runtime.summary import finish

    config = sil_config(argv)
    summary, result = run_sil(config)
    return finish(
        summary, result, config.run, "pressor sil", drug=config.drug, weight_kg=config.weight_kg
    )


def main(command: str, argv: list[str]) -> int:
    """Entry point for ``pressor sil`` (see the module docstring for exit codes)."""
    # --help and a bad option answer before the link, the recorder and numpy load
    early = parse_first(f"pressor {command}", sil_parser(), argv)
    if early is not None:
        return early
    from pressor.runtime.session import run_guarded

    return run_guarded(f"pressor {command}", _main, argv)
