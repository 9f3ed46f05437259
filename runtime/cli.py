"""``pressor sil``, ``pressor run`` and ``pressor faults``: the runtime's command line.

``pressor sil`` is the main job: it starts the device (``python -m pressor device --port ...``) as
its own process — the runtime never imports ``hil_sim`` —, connects to it over a pseudo-terminal
(a real tty to pyserial), signs the link (a fresh key per run unless ``--signing-key``), runs the
loop in lockstep (or ``--realtime``), records everything to an ``.rrd``, prints the DESIGN.md §3
metric summary and the ``rerun FILE.rrd`` command to replay it.

``pressor run --port DEV`` is the runtime end alone (a device on a real cable or a ``socat`` pty).

``pressor faults`` lists the injectable fault kinds (``--fault KIND[:ARGS]``) with their arguments,
defaults, detection bounds and safe states, then what the supervisor detects.

Faults. ``pressor sil --fault KIND[:ARGS]`` (repeatable) passes each fault to the device process,
which injects it (the runtime never imports ``hil_sim``; the control path learns of a fault only
through its inputs). Faults a scenario file declares (``[[faults]]``) are injected by the device
too and read here from the same file. After the run, the summary's ``faults`` list scores each
scheduled fault from the supervisor's per-tick log (:func:`contracts.faults.fault_report`):
``kind``, ``start_tick``, ``detected_tick``, ``latency_ticks`` and its documented bound,
``safe_state_s``, ``max_reentry_step_ml_h``; ``commands_out_of_range`` counts commands outside
[0, max] (always 0 - the run exits 1 otherwise). ``pressor run --fault ...`` scores a schedule
injected by a device started by hand.

Files. The ``.rrd``, ``.tlog``, ``--summary`` and ``--timing`` files are written to a hidden
temporary name and renamed when the run succeeds; a failed run leaves earlier files untouched.

Summary JSON (``--summary``): run identity, the §3 metrics (``contracts.metrics.run_metrics``,
defined in ``docs/METRICS.md``; with ``pressor sil`` the step metrics stop at the first disturbance
and each hemorrhage or bolus of the scenario file gets a ``disturbances`` record; with ``pressor
run`` the device's scenario is not known, so those are null) plus ``commands_out_of_range``, the
supervisor's account and the link's error counts. It holds only values that are functions of the
seed (no wall-clock timing), so two runs give identical files;
loop timing (p50/p99/max) is printed and recorded under ``/loop``.

``reachable`` is inferred from the run, since the runtime does not know the patient: false when the
pump sat at its limit for the whole final 10 % of the run with MAP still more than 5 mmHg below the
target.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

USAGE_EXIT = 2
DEFAULT_SCENARIO = "paper-tracking"
DEFAULT_PATIENT_SEED = 1
DEFAULT_DURATION_S = 1800.0
DEFAULT_RATE_HZ = 10.0


class UsageError(Exception):
    """Bad input: the message names the option or file, the value and the allowed range."""


# ---------------------------------------------------------------------- argument parsing
def _positive(name: str, high: float):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r}: not a number") from None
        if not (math.isfinite(value) and 0.0 < value <= high):
            raise argparse.ArgumentTypeError(f"{name} {text!r}: allowed (0, {high:g}]")
        return value

    return parse


def _cpu_latency(text: str) -> int | None:
    from runtime.cpu_latency import MAX_LATENCY_US

    if text == "off":
        return None
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--cpu-latency {text!r}: allowed off or an integer in [0, {MAX_LATENCY_US}] us"
        ) from None
    if not 0 <= value <= MAX_LATENCY_US:
        raise argparse.ArgumentTypeError(
            f"--cpu-latency {text!r}: allowed off or [0, {MAX_LATENCY_US}] us"
        )
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--patient-seed {text!r}: not an integer") from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"--patient-seed {text!r}: allowed [0, 2**32)")
    return value


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        raise UsageError(f"{self.prog}: {message}")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--controller",
        default="lpv",
        help="lpv (default), pi, smith[:LAMBDA_S] (Smith predictor, lambda 30 s), or a generated .py",
    )
    p.add_argument(
        "--rate",
        type=_positive("--rate", 1000.0),
        default=DEFAULT_RATE_HZ,
        help="loop rate in Hz (default 10)",
    )
    p.add_argument("--realtime", action="store_true", help="wall clock instead of lockstep")
    p.add_argument("--rrd", type=Path, help="rerun recording to write (FILE.rrd)")
    p.add_argument("--tlog", type=Path, help="MAVLink telemetry log of every frame")
    p.add_argument("--summary", type=Path, help="write the metric summary as JSON")
    p.add_argument(
        "--timing",
        type=Path,
        help="write loop timing (p50/p99/max), wall time and link counters as JSON"
        " (host-dependent, unlike --summary)",
    )
    p.add_argument("--signing-key", type=Path, help="32-byte key file (raw or 64 hex chars)")
    p.add_argument(
        "--sched-faults",
        choices=("advise", "hold"),
        default="advise",
        help="scheduling outside the design box / rate bounds: advisory alarm (default) or hold",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="KIND[:ARGS]",
        help="inject a fault (repeatable; 'pressor faults' lists kinds, arguments, defaults)",
    )
    p.add_argument(
        "--stall-timeout",
        type=_positive("--stall-timeout", 3600.0),
        default=10.0,
        help="lockstep: give up after this many wall seconds without a sample (default 10)",
    )
    p.add_argument(
        "--cpu-latency",
        type=_cpu_latency,
        default=0,
        metavar="US|off",
        help="hold the host's CPU wake-up latency at US microseconds during the run"
        " (/dev/cpu_dma_latency, best effort, usually needs root; default 0: idle CPUs poll"
        " instead of halting, 2x faster lockstep on a VM); off: make no request",
    )


def _sil_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="pressor sil", description="device process + runtime over a serial link")
    _common(p)
    p.add_argument("--scenario", default=DEFAULT_SCENARIO, help="scenario name (pressor scenarios)")
    p.add_argument("--patient-seed", type=_seed, default=DEFAULT_PATIENT_SEED)
    p.add_argument(
        "--duration",
        type=_positive("--duration", 7 * 86400.0),
        default=DEFAULT_DURATION_S,
        help="simulated time in s (default 1800)",
    )
    p.add_argument("--link", default="pty", help="pty (default) or a pyserial URL / device path")
    p.add_argument("--no-signing", action="store_true", help="run the link unsigned")
    p.add_argument(
        "--cpu",
        type=_cpu,
        default="auto",
        metavar="auto|none|N|N,M",
        help="lockstep CPU placement: auto (default) the loop thread on the CPU it is on and the"
        " device on another; N both on CPU N; N,M the loop on N and the device on M; none let"
        " the scheduler place them. Ignored with --realtime",
    )
    return p


def _cpu(text: str) -> str | tuple[int, int]:
    if text in ("auto", "none"):
        return text
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    hint = f"allowed auto, none, N or N,M with N and M in {allowed}"
    try:
        cpus = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cpu {text!r}: {hint}") from None
    if len(cpus) not in (1, 2) or any(c not in allowed for c in cpus):
        raise argparse.ArgumentTypeError(f"--cpu {text!r}: {hint}")
    return (cpus[0], cpus[-1])


def lockstep_cpus(choice: str | tuple[int, int], realtime: bool) -> tuple[int, int] | None:
    """``(loop CPU, device CPU)`` for a lockstep run, or ``None`` (no pinning).

    ``auto`` puts the two ends on two different CPUs: the loop thread stays on the CPU it runs on
    and the device takes another. Each end then keeps its caches, and the runtime records tick
    k while the device computes tick k+1 (recording happens after the command is sent). With
    the CPU wake-up latency request held (:mod:`runtime.cpu_latency`), two CPUs beat one
    (development VM, LPV, 30 min at 10 Hz: 610-680x split, 620-650x unpinned, 460-470x on one
    CPU); without it split and unpinned give ~400x and one CPU ~330x. ``benchmarks/sil.py``
    measures the bare pty round trip each way. Only the loop thread is pinned; the recorder's
    rerun threads stay free.
    """
    if choice == "none" or realtime or not hasattr(os, "sched_setaffinity"):
        return None
    if isinstance(choice, tuple):
        return choice
    allowed = os.sched_getaffinity(0)
    if len(allowed) < 2:
        return None
    here = _current_cpu(allowed)
    return here, min(allowed - {here})


def _current_cpu(allowed: set[int]) -> int:
    """The CPU this thread last ran on (``/proc/thread-self/stat`` field 39), else the lowest."""
    try:
        text = Path("/proc/thread-self/stat").read_text()
        cpu = int(text[text.rindex(")") + 2 :].split()[36])
        if cpu in allowed:
            return cpu
    except (OSError, ValueError, IndexError):
        pass
    return min(allowed)


class _Pinned:
    """Run the calling thread on ``cpu`` inside the block (``None``: no change)."""

    def __init__(self, cpu: int | None) -> None:
        self.cpu = cpu
        self._saved: set[int] | None = None

    def __enter__(self) -> None:
        if self.cpu is not None:
            self._saved = os.sched_getaffinity(0)
            os.sched_setaffinity(0, {self.cpu})

    def __exit__(self, *exc: object) -> None:
        if self._saved is not None:
            os.sched_setaffinity(0, self._saved)


def _run_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="pressor run", description="the controller runtime alone on a serial port")
    _common(p)
    p.add_argument("--port", required=True, help="device path or pyserial URL")
    p.add_argument(
        "--ticks", type=int, default=0, help="stop after N ticks (0: when the device ends)"
    )
    return p


# ---------------------------------------------------------------------- summary
def _step_of(
    t: np.ndarray, map_mmhg: np.ndarray, target: np.ndarray
) -> tuple[float | None, float | None]:
    """The target step (time s, size mmHg) as the runtime sees it.

    The first change of the target; or, if the target never changes, the distance from the first
    MAP sample to the target at the first tick (a run that starts ≥ 1 mmHg away from its target,
    like ``paper-tracking`` whose step is at t = 0). ``(None, None)`` otherwise.
    """
    finite = np.isfinite(target)
    if not finite.any():
        return None, None
    i0 = int(np.argmax(finite))
    first = target[i0]
    changed = np.flatnonzero(finite & (target != first))
    if changed.size:
        i = int(changed[0])
        return float(t[i]), float(target[i] - first)
    d = float(first - map_mmhg[i0])
    if math.isfinite(d) and abs(d) >= 1.0:
        return float(t[i0]), d
    return None, None


def _reachable(map_mmhg: np.ndarray, target: np.ndarray, cmd: np.ndarray, umax: float) -> bool:
    n_tail = max(1, int(round(0.1 * cmd.size)))
    at_limit = bool(np.all(cmd[-n_tail:] >= umax * (1.0 - 1e-6)))
    below = np.nanmedian(target[-n_tail:] - map_mmhg[-n_tail:]) > 5.0
    return not (at_limit and below)


def build_summary(
    result: Any,
    identity: dict[str, Any],
    max_rate_ml_h: float,
    noisy: bool,
    faults: list[dict[str, Any]] | None = None,
    events: list[tuple[str, float]] | None = None,
):
    """The JSON-ready summary of a run: identity, §3 metrics, supervisor and link account, and
    the scored fault list when faults were scheduled. ``events`` are the scenario's disturbance
    events (``contracts.metrics.run_metrics``); ``None`` when not known (``pressor run``). The
    rate metrics (drug total, max rate, time at limit) use the rate the pump reported delivering."""
    from contracts.metrics import run_metrics
    from runtime.trajectory import held_delivered_ml_h

    tr = result.trajectory
    t, y, r, u = tr["sim_time_s"], tr["map_mmhg"], tr["target_mmhg"], tr["command_ml_h"]
    if t.size < 2:
        metrics: dict[str, Any] = {"error": "fewer than 2 ticks: no metrics"}
    else:
        step_t, step_d = _step_of(t, y, r)
        metrics = run_metrics(
            t,
            y,
            r,
            held_delivered_ml_h(tr["delivered_ml_h"]),
            max_rate_ml_h,
            step_time_s=step_t,
            step_mmhg=step_d,
            noisy=noisy,
            reachable=_reachable(y, r, u, max_rate_ml_h),
            events=events,
        )
    metrics["commands_out_of_range"] = result.commands_out_of_range
    link = result.link
    extra: dict[str, Any] = {}
    if faults is not None:
        extra["faults"] = faults
    return {
        **extra,
        "commands_out_of_range": result.commands_out_of_range,
        **identity,
        "ticks": int(t.size),
        "ended": result.ended,
        "metrics": metrics,
        "supervisor": {
            "detections": result.detections,
            "ticks_in_state": result.ticks_in_state,
            "transitions": result.transitions[:100],
        },
        "link_errors": {
            k: link[k]
            for k in (
                "bad_crc",
                "seq_gaps",
                "frames_lost",
                "refused_unsigned",
                "refused_bad_signature",
            )
        },
    }


def _fmt(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def print_summary(summary: dict[str, Any], timing: dict[str, Any], out: Any = None) -> None:
    """Human-readable summary (metrics, supervisor, loop timing) to ``out`` (default stdout)."""
    out = sys.stdout if out is None else out
    print(
        f"run: controller {summary.get('controller')}  scenario {summary.get('scenario')}"
        f"  patient seed {summary.get('patient_seed')}  {summary['ticks']} ticks"
        f"  ({summary['ended']})",
        file=out,
    )
    print("metrics (defined in docs/METRICS.md):", file=out)
    metrics = summary["metrics"]
    for k, v in metrics.items():
        if k != "disturbances":
            print(f"  {k:<24} {_fmt(v)}", file=out)
    for d in metrics.get("disturbances") or []:
        print(
            f"  {d['kind']} at {_fmt(d['start_s'])} s: peak deviation"
            f" {_fmt(d['peak_deviation_mmhg'])} mmHg, recovery {_fmt(d['recovery_s'])} s,"
            f" IAE {_fmt(d['iae_mmhg_s'])} mmHg·s",
            file=out,
        )
    sup = summary["supervisor"]
    states = ", ".join(f"{k} {v}" for k, v in sup["ticks_in_state"].items() if v)
    print(f"supervisor: ticks in state: {states}", file=out)
    if sup["detections"]:
        print(f"  faults detected: {sup['detections']}", file=out)
    print(
        "loop timing: exec p50/p99/max {exec_p50_us:.1f}/{exec_p99_us:.1f}/{exec_max_us:.1f} us;"
        " lateness p50/p99/max {lateness_p50_us:.1f}/{lateness_p99_us:.1f}/{lateness_max_us:.1f}"
        " us; overruns {overruns}; skipped {skipped_periods}".format(**timing),
        file=out,
    )
    errs = {k: v for k, v in summary["link_errors"].items() if v}
    print(f"link: {'clean' if not errs else errs}", file=out)
    if summary.get("faults"):
        print_fault_table(summary["faults"], summary["commands_out_of_range"], out)


def print_fault_table(faults: list[dict[str, Any]], out_of_range: int, out: Any = None) -> None:
    """The per-fault table: detection latency (ticks, bound), safe-state time, re-entry step."""
    out = sys.stdout if out is None else out
    print(
        f"{'fault':<18} {'start':>6} {'detect':>6} {'lat':>4} {'bound':>5} {'ok':>3}"
        f" {'safe_s':>7} {'reentry_ml_h':>12}  detected as",
        file=out,
    )
    for f in faults:
        if not f["applicable"]:
            print(f"{f['kind']:<18} {f['start_tick']:>6}  n/a (controller not scheduled)", file=out)
            continue
        ok = {True: "yes", False: "NO", None: "-"}[f["within_bound"]]
        print(
            f"{f['kind']:<18} {f['start_tick']:>6} {_fmt(f['detected_tick']):>6}"
            f" {_fmt(f['latency_ticks']):>4} {_fmt(f['bound_ticks']):>5} {ok:>3}"
            f" {f['safe_state_s']:>7.1f} {f['max_reentry_step_ml_h']:>12.3f}"
            f"  {','.join(f['detected_as']) or '-'}",
            file=out,
        )
    print(f"commands out of [0, max]: {out_of_range}", file=out)


def _tmp_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def _write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    tmp = _tmp_name(path)
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")
    os.replace(tmp, path)


# ---------------------------------------------------------------------- running
def _load_controller(spec: str, period_s: float):
    from runtime.controller_loader import ControllerSpecError, load_controller

    try:
        return load_controller(spec, sample_period_s=period_s)
    except ControllerSpecError as exc:
        hint = ""
        if spec == "lpv":
            hint = (
                " (the shipped LPV module is generated by 'pressor codegen --target python"
                " --out runtime/generated'; use --controller pi meanwhile)"
            )
        raise UsageError(f"--controller {spec}: {exc}{hint}") from None


def _check_out_path(opt: str, path: Path | None, suffix: str | None = None) -> None:
    if path is None:
        return
    if suffix and path.suffix != suffix:
        raise UsageError(f"{opt} {path}: expected a {suffix} file name")
    if not path.parent.resolve().is_dir():
        raise UsageError(f"{opt} {path}: directory {path.parent} does not exist")


def _signing(args: argparse.Namespace, allow_generate: bool):
    from runtime.link.endpoint import Signing

    if args.signing_key is not None:
        try:
            return Signing.from_file(args.signing_key)
        except (OSError, ValueError) as exc:
            raise UsageError(f"--signing-key {args.signing_key}: {exc}") from None
    if allow_generate and not getattr(args, "no_signing", False):
        return Signing.generate()
    return None


def run_runtime(
    port: Any,
    args: argparse.Namespace,
    identity: dict[str, Any],
    signing: Any,
    on_connected: Any = None,
    peer_alive: Any = None,
    handshake_timeout_s: float = 30.0,
) -> tuple[dict[str, Any], Any, Path | None]:
    """Handshake, build controller/supervisor/recorder, run the loop; return (summary, result, rrd)."""
    from runtime.cpu_latency import CpuLatencyRequest
    from runtime.link.endpoint import LINK_LOCKSTEP, LINK_REALTIME, Hello, LinkEndpoint, LinkError
    from runtime.link.tlog import TlogWriter
    from runtime.loop import Loop
    from runtime.supervisor import Supervisor
    from runtime.supervisor_config import supervisor_config_for

    period_s = 1.0 / args.rate
    controller = _load_controller(args.controller, period_s)
    tlog = TlogWriter(args.tlog) if args.tlog is not None else None
    ok = False
    ep = LinkEndpoint(port, "runtime", signing=signing, tlog=tlog)
    recorder = None
    try:
        mode = LINK_REALTIME if args.realtime else LINK_LOCKSTEP
        name = (
            Path(args.controller).stem if args.controller not in ("pi", "lpv") else args.controller
        )
        hello = Hello(name[:32], sample_period_s=period_s, link_mode=mode)
        waited = 0.0
        while True:  # short attempts, so a device process that died is noticed at once
            try:
                peer = ep.handshake(hello, timeout_s=0.25)
                break
            except LinkError:
                waited += 0.25
                if (peer_alive is not None and not peer_alive()) or waited >= handshake_timeout_s:
                    raise
        if on_connected is not None:
            on_connected()
        if abs(peer.sample_period_s - period_s) > 1e-9:
            raise UsageError(
                f"device sample_period_s {peer.sample_period_s} s differs from --rate"
                f" {args.rate} Hz (period {period_s} s)"
            )
        identity = {
            **identity,
            "scenario": peer.name,
            "patient_seed": peer.patient_seed,
            "sensor_noise_mmhg": float(peer.sensor_noise_mmhg),
        }
        sup = Supervisor(
            supervisor_config_for(
                controller, peer.sensor_noise_mmhg, sched_action=args.sched_faults
            )
        )
        rrd = args.rrd
        if rrd is not None:
            from runtime.recorder import Recorder

            label = (
                f"{identity['controller']}|{peer.name}|seed{peer.patient_seed}|{args.rate}Hz"
                f"|{'realtime' if args.realtime else 'lockstep'}"
            )
            recorder = Recorder(rrd, run_label=label)
        loop = Loop(controller, sup, ep, recorder=recorder, heartbeat_every=round(args.rate))
        with CpuLatencyRequest(getattr(args, "cpu_latency", None)) as wake:
            if args.realtime:
                n = peer.n_ticks if peer.n_ticks else getattr(args, "ticks", 0)
                result = loop.run_realtime(n)
            else:
                n = getattr(args, "ticks", 0) or peer.n_ticks
                cpus = getattr(args, "cpus", None)
                with _Pinned(None if cpus is None else cpus[0]):  # rerun's threads exist already
                    result = loop.run_lockstep(n, stall_timeout_s=args.stall_timeout)
        result.host = {"cpu_latency": wake.status, "cpus": getattr(args, "cpus", None)}
        if recorder is not None:
            recorder.close()
            recorder = None
        specs = getattr(args, "fault_specs", None)
        report = None
        if specs:
            from contracts.faults import fault_report
            from runtime.supervisor_config import FAULT_BITS, sched_limits_of

            report = fault_report(
                specs,
                result.trajectory,
                FAULT_BITS,
                period_s,
                scheduled=sched_limits_of(controller)[0] is not None,
            )
        summary = build_summary(
            result,
            identity,
            controller.max_rate_ml_h,
            noisy=peer.sensor_noise_mmhg > 0.0,
            faults=report,
            events=getattr(args, "events", None),
        )
        ok = True
        return summary, result, rrd
    finally:
        if recorder is not None:
            recorder.abort()
        ep.close()
        if tlog is not None:
            tlog.close(commit=ok)


def _finish(summary: dict[str, Any], result: Any, rrd: Path | None, args) -> int:
    print_summary(summary, result.timing)
    if result.host:
        print(f"host: cpu wake-up latency {result.host['cpu_latency']}")
    if args.summary is not None:
        _write_json_atomic(args.summary, summary)
        print(f"summary: {args.summary}")
    if args.timing is not None:
        status = {
            "loop": result.timing,
            "run_wall_s": result.wall_s,
            "sim_s": summary["ticks"] / summary["rate_hz"],
            "link": result.link,
            "host": result.host,
        }
        _write_json_atomic(args.timing, status)
        print(f"timing: {args.timing}")
    if rrd is not None:
        print(f"recording: {rrd}\nreplay:    rerun {rrd}")
    return 1 if summary["metrics"].get("commands_out_of_range") else 0


def _main_sil(argv: list[str]) -> int:
    args = _sil_parser().parse_args(argv)
    if args.rrd is None:
        args.rrd = Path(
            f"pressor_sil_{Path(args.controller).stem}_{args.scenario}_seed{args.patient_seed}.rrd"
        )
    _check_out_path("--rrd", args.rrd, ".rrd")
    _check_out_path("--tlog", args.tlog)
    _check_out_path("--summary", args.summary)
    _check_out_path("--timing", args.timing)
    _load_controller(args.controller, 1.0 / args.rate)  # fail fast, before a device starts
    args.fault_specs = _fault_specs(args.fault)
    args.fault_specs += _scenario_faults(args.scenario, len(args.fault_specs))
    args.events = _scenario_events(args.scenario)
    signing = _signing(args, allow_generate=True)
    identity = {
        "controller": args.controller,
        "link": args.link,
        "mode": "realtime" if args.realtime else "lockstep",
        "rate_hz": args.rate,
        "duration_s": args.duration,
        "signed": signing is not None,
    }
    if args.link != "pty":
        raise UsageError(
            f"--link {args.link}: pressor sil starts the device on a pty it creates; for a device"
            " on another port run 'pressor device --port ...' there and 'pressor run --port"
            f" {args.link}' here"
        )
    from runtime.link.transport import PtyPair

    pair = PtyPair.open()
    with tempfile.TemporaryDirectory(prefix="pressor-sil-") as tmp:
        cmd = [
            sys.executable,
            "-m",
            "pressor",
            "device",
            "--port",
            pair.follower_path,
            "--scenario",
            args.scenario,
            "--patient-seed",
            str(args.patient_seed),
            "--duration",
            repr(args.duration),
            "--rate",
            repr(args.rate),
        ]
        if args.realtime:
            cmd.append("--realtime")
        args.cpus = cpus = lockstep_cpus(args.cpu, args.realtime)
        if cpus is not None:
            cmd += ["--cpu", str(cpus[1])]
        for text in args.fault:
            cmd += ["--fault", text]
        if any(f.info.group == "link" for f in args.fault_specs):
            cmd += ["--retransmit", "0.05"]  # wall-clock resend of lost ticks; trajectory-neutral
        if signing is not None:
            cmd += ["--signing-key", str(signing.write(Path(tmp) / "signing.key"))]
        device_log = Path(tmp) / "device.log"
        with open(device_log, "wb") as log:
            proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        port = pair.leader_port()
        try:
            summary, result, rrd = run_runtime(
                port,
                args,
                identity,
                signing,
                on_connected=pair.close_follower,
                peer_alive=lambda: proc.poll() is None,
            )
        except Exception:
            _stop(proc)
            text = device_log.read_text(errors="replace").strip()
            if proc.returncode == USAGE_EXIT and text:
                raise UsageError(text.splitlines()[-1]) from None
            if text:
                print(f"device output:\n{text}", file=sys.stderr)
            raise
        finally:
            pair.close()
        code = _stop(proc, grace_s=10.0)
        if code not in (0, None):
            text = device_log.read_text(errors="replace").strip()
            print(f"device exited with {code}:\n{text}", file=sys.stderr)
    status = _finish(summary, result, rrd, args)
    return status


def _fault_specs(texts: list[str]) -> list[Any]:
    from contracts.faults import FaultSpecError, parse_faults

    try:
        return parse_faults(texts)
    except FaultSpecError as exc:
        raise UsageError(str(exc)) from None


def _scenario_path(scenario: str) -> Path:
    """The file the device loads for ``--scenario`` (a shipped name or a ``.toml`` path)."""
    if scenario.endswith(".toml") or "/" in scenario:
        return Path(scenario)
    return Path(__file__).resolve().parents[1] / "hil_sim" / "scenarios" / f"{scenario}.toml"


def _scenario_events(scenario: str) -> list[tuple[str, float]] | None:
    """The disturbance events ``(kind, start_s)`` of the device's scenario file (read, not
    imported), for the metrics; ``None`` if the file cannot be read (the device reports why)."""
    import tomllib

    from contracts.metrics import EVENT_KINDS

    try:
        data = tomllib.loads(_scenario_path(scenario).read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError):
        return None
    raw = data.get("disturbances", [])
    tables = [d for d in raw if isinstance(d, dict)] if isinstance(raw, list) else []
    return [
        (str(d["kind"]), float(d["start_s"]))
        for d in tables
        if d.get("kind") in EVENT_KINDS and isinstance(d.get("start_s"), (int, float))
    ]


def _scenario_faults(scenario: str, first_index: int) -> list[Any]:
    """The ``[[faults]]`` the device will inject from its scenario file (read, not imported)."""
    from contracts.faults import FaultSpecError, scenario_file_faults

    path = _scenario_path(scenario)
    if not path.is_file():
        return []
    try:
        return scenario_file_faults(path, first_index)
    except FaultSpecError as exc:
        raise UsageError(str(exc)) from None


def _stop(proc: subprocess.Popen, grace_s: float = 2.0) -> int | None:
    """Wait for our device process; terminate it (by its pid) if it does not exit in time."""
    try:
        return proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        proc.terminate()
        try:
            return proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait()


def _main_run(argv: list[str]) -> int:
    args = _run_parser().parse_args(argv)
    if args.ticks < 0:
        raise UsageError(f"--ticks {args.ticks}: allowed >= 0")
    _check_out_path("--rrd", args.rrd, ".rrd")
    _check_out_path("--tlog", args.tlog)
    _check_out_path("--summary", args.summary)
    _check_out_path("--timing", args.timing)
    _load_controller(args.controller, 1.0 / args.rate)
    args.fault_specs = _fault_specs(args.fault)
    signing = _signing(args, allow_generate=False)
    from runtime.link.transport import fast_port, open_port

    try:
        port = fast_port(open_port(args.port))
    except Exception as exc:  # pyserial raises several types for a bad path/URL
        raise UsageError(f"--port {args.port}: cannot open: {exc}") from None
    identity = {
        "controller": args.controller,
        "link": args.port,
        "mode": "realtime" if args.realtime else "lockstep",
        "rate_hz": args.rate,
        "signed": signing is not None,
    }
    summary, result, rrd = run_runtime(port, args, identity, signing)
    return _finish(summary, result, rrd, args)


def _main_faults(argv: list[str]) -> int:
    from contracts.faults import catalogue_rows
    from runtime.supervisor_config import SupervisorConfig, detection_bounds

    p = _Parser(prog="pressor faults", description="fault kinds the supervisor detects")
    p.add_argument("--rate", type=_positive("--rate", 1000.0), default=DEFAULT_RATE_HZ)
    args = p.parse_args(argv)
    cfg = SupervisorConfig(sample_period_s=1.0 / args.rate, stale_after_s=3.5 / args.rate)
    print(
        "Injectable faults: --fault KIND[:key=value,...] on pressor sil / device (bare numbers"
        " = start_s, duration_s; s of sim time). Bounds are ticks at 10 Hz after the first"
        " fault tick; watchdog period = link_loss_after_s = 1 s."
    )
    for kind, fargs, bound, safe in catalogue_rows():
        print(f"  {kind}\n      args:   {fargs}\n      detect: {bound}\n      safe:   {safe}")
    print()
    print(f"Faults the runtime supervisor detects (defaults at {args.rate:g} Hz):")
    rows = detection_bounds(cfg)
    width = max(len(k) for k, _ in rows)
    for kind, text in rows:
        print(f"  {kind:<{width}}  {text}")
    print(
        "Scheduling checks use the design box and rate bounds a generated controller declares"
        " (GRID_LO, GRID_HI, RATE_BOUNDS); the PI baseline is not scheduled. Default for"
        " pressor sil/run: advisory (--sched-faults advise)."
    )
    return 0


def main(command: str, argv: list[str]) -> int:
    """Entry point for ``pressor sil | run | faults`` (see the module docstring).

    Returns 0 on success, 1 if the run completed but a check failed (or the device stalled),
    2 on bad usage or input (one line on stderr naming the option or file, value and range).
    """
    from runtime.link.endpoint import LinkError
    from runtime.loop import DeviceStalled

    handlers = {"sil": _main_sil, "run": _main_run, "faults": _main_faults}
    if command not in handlers:
        print(f"runtime.cli: unknown command {command!r}", file=sys.stderr)
        return USAGE_EXIT
    try:
        return handlers[command](argv)
    except UsageError as exc:
        print(str(exc), file=sys.stderr)
        return USAGE_EXIT
    except (DeviceStalled, LinkError) as exc:
        print(f"pressor {command}: {exc}", file=sys.stderr)
        return 1
    except SystemExit as exc:  # argparse --help
        return int(exc.code or 0)
