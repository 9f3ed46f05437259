"""The runtime's command-line options, shared by ``pressor run`` and ``pressor sil``.

:func:`add_run_options` adds them to a parser, each help naming its default, unit and range
(:func:`positive` and the ``--cpu-latency`` parser refuse a bad value at parse time, naming the
option); :func:`pressor.runtime.inputs.config.run_config` checks the parsed namespace as a whole
and freezes it.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from pressor.contracts.checks import check_int_range, check_range
from pressor.runtime.core.supervisor_config import DEFAULT_SAMPLE_AGE_LIMIT_S
from pressor.runtime.estimation.sources import SOURCES
from pressor.runtime.shell.cpu_latency import MAX_LATENCY_US
from pressor.runtime.shell.status import DEFAULT_STATUS_EVERY_S
from pressor.runtime.shell.viewer import DEFAULT_VIEW_PORT, VIEW_PORT_MAX, VIEW_PORT_MIN

#: what ``--schedule`` means, for the help of every command that takes it
SCHEDULE_HELP = (
    "where the controller's K, T, tau come from: oracle = the device's SCHEDULING_PARAMS (a"
    " simulator's truth; research comparisons, needs a device that sends them), estimated ="
    " the runtime's online estimator from MAP and the delivered rate (falls back to the nominal"
    " patient until it has learned or when its health check rejects an estimate), nominal ="
    " the nominal patient's constants (a fixed-gain controller), validated = opt-in: the nominal"
    " patient's K with T and tau slewed, inside the design box at 0.9x the certified rates,"
    " toward a model that predicts the MAP better than the nominal one, cautious = for a design"
    " on a log-K scale (lpv:cautious, lpv:norepinephrine-cautious): K starts at the most"
    " sensitive patient of the design's population and falls only on the MAP's evidence, at"
    " the certified rate (docs/SCHEDULING.md)"
)
#: what every command's ``--schedule`` help ends with: its default (pressor.runtime.inputs.defaults)
SCHEDULE_DEFAULT_HELP = (
    "; default: cautious for a design on a log-K scale (the default controllers), estimated for"
    " any other"
)
#: what every command's ``--controller`` help says of its default
CONTROLLER_DEFAULT_HELP = (
    "default: the drug's design on a log-K scale, lpv:cautious for phenylephrine,"
    " lpv:norepinephrine-cautious for norepinephrine (docs/DRUGS.md)"
)

DEFAULT_RATE_HZ = 10.0
#: fastest loop rate accepted (Hz)
MAX_RATE_HZ = 1000.0


#: what ``--on-stop`` may choose: the last command of a run a signal stopped
STOP_COMMANDS = ("held", "zero")


def positive(name: str, high: float) -> Callable[[str], float]:
    """An argparse type: a number in (0, ``high``] for option ``name``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r}: not a number") from None
        return check_range(name, value, 0.0, high, lo_open=True, error=argparse.ArgumentTypeError)

    return parse


def _view_port(text: str) -> int:
    """An argparse type: ``--view-port``, an integer in [VIEW_PORT_MIN, VIEW_PORT_MAX]."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--view-port {text!r}: not an integer") from None
    return check_int_range(
        "--view-port", value, VIEW_PORT_MIN, VIEW_PORT_MAX, error=argparse.ArgumentTypeError
    )


def _cpu_latency(text: str) -> int | None:
    """``off`` -> None (no request), ``hold`` -> 0 µs, else an integer in [0, MAX_LATENCY_US] µs."""
    if text == "off":
        return None
    if text == "hold":
        return 0
    allowed = f"allowed off, hold (0 us) or an integer in [0, {MAX_LATENCY_US}] us"
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cpu-latency {text!r}: {allowed}") from None
    if not 0 <= value <= MAX_LATENCY_US:
        raise argparse.ArgumentTypeError(f"--cpu-latency {text!r}: {allowed}")
    return value


def add_run_options(p: argparse.ArgumentParser) -> None:
    """Add the runtime's options (controller, schedule, rate, outputs, signing, faults, timing) to
    ``p``; ``--controller`` and ``--schedule`` default to None, resolved by :func:`run_config`
    (:mod:`pressor.runtime.inputs.defaults`)."""
    from pressor.runtime.inputs.controller_loader import design_specs

    designs = design_specs()
    p.add_argument(
        "--controller",
        default=None,
        help=f"{CONTROLLER_DEFAULT_HELP}; {', '.join(designs)} (the shipped designs,"
        " docs/DRUGS.md and docs/SCHEDULING.md; pressor designs lists them), pi, smith[:LAMBDA_S]"
        " (Smith predictor, closed-loop time constant LAMBDA_S in s, default 30 s), a generated .py, or your own"
        " class: MODULE:CLASS[:ARGS], FILE.py:CLASS[:ARGS] or an installed 'pressor.controllers'"
        " entry point NAME[:ARGS] (ARGS: key=value,...; pressor.runtime.inputs.controller_plugin)",
    )
    p.add_argument(
        "--schedule",
        choices=SOURCES,
        default=None,
        help=f"{SCHEDULE_HELP}{SCHEDULE_DEFAULT_HELP}",
    )
    p.add_argument(
        "--rate",
        type=positive("--rate", MAX_RATE_HZ),
        default=DEFAULT_RATE_HZ,
        help="loop rate (Hz)",
    )
    p.add_argument(
        "--realtime",
        action="store_true",
        help="wall clock instead of lockstep (as fast as possible)",
    )
    p.add_argument(
        "--rrd",
        type=Path,
        help="rerun recording to write (FILE.rrd; default: pressor sil writes"
        " pressor_sil_CONTROLLER_SCENARIO_seedN.rrd, pressor run none)",
    )
    p.add_argument(
        "--view",
        action="store_true",
        help="show the run live in rerun's viewer, with the recording's layout (docs/VIEWER.md):"
        " the native viewer where there is a display (DISPLAY or WAYLAND_DISPLAY set), else the"
        " web viewer served on 127.0.0.1 (the URL to open is printed on stderr); the recording"
        " (--rrd) is written as well. The viewer stays after the run (a web one until its printed"
        " pid is killed); closing it leaves the run going; one already on --view-port is reused",
    )
    p.add_argument(
        "--view-port",
        type=_view_port,
        default=DEFAULT_VIEW_PORT,
        metavar="PORT",
        help=f"--view: the viewer's gRPC port on 127.0.0.1, [{VIEW_PORT_MIN}, {VIEW_PORT_MAX}]"
        " (the web viewer's page on PORT+1)",
    )
    p.add_argument("--tlog", type=Path, help="MAVLink telemetry log of every frame (FILE.tlog)")
    p.add_argument("--summary", type=Path, help="write the metric summary as JSON (FILE.json)")
    p.add_argument(
        "--timing",
        type=Path,
        help="write loop timing (p50/p99/max), wall time and link counters as JSON"
        " (host-dependent, unlike --summary)",
    )
    p.add_argument(
        "--signing-key",
        type=Path,
        help="32-byte key file (raw or 64 hex chars); pressor run defaults to the one"
        " 'pressor keygen' wrote, pressor sil to a fresh key per run",
    )
    p.add_argument(
        "--no-signing", action="store_true", help="run the link unsigned (warned; default: signed)"
    )
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
        type=positive("--stall-timeout", 3600.0),
        default=10.0,
        help="lockstep: give up after this many wall-clock seconds without a sample (s)",
    )
    p.add_argument(
        "--on-stop",
        choices=STOP_COMMANDS,
        default="held",
        help="the last command SIGINT / SIGTERM sends before the run ends: held (default: the"
        " safe rate, which is the last rate held, mode SAFE: the pump keeps the patient's"
        " infusion) or zero (0 ml/h, mode STOP: the infusion stops)",
    )
    p.add_argument(
        "--status-every",
        type=positive("--status-every", 3600.0),
        default=DEFAULT_STATUS_EVERY_S,
        metavar="S",
        help="time between two status lines on stderr (s, wall clock: run time, state, MAP, target,"
        " dose, alarms) while the run lasts; pressor sil prints them in real time only, lockstep"
        " shows its progress bar instead",
    )
    p.add_argument("--quiet", action="store_true", help="no status lines")
    p.add_argument(
        "--sample-age-limit-s",
        type=positive("--sample-age-limit-s", 60.0),
        default=DEFAULT_SAMPLE_AGE_LIMIT_S,
        help="the runtime holds the newest MAP sample and uses it until it is this old (s; a"
        " sample repeated with the HELD quality bit ages from the last new one), then"
        " STALE_SAMPLE; at least one loop period, default 3 s: three updates of a 1 Hz monitor",
    )
    p.add_argument(
        "--cpu-latency",
        type=_cpu_latency,
        default=None,
        metavar="off|hold|US",
        help="host-wide CPU wake-up latency request while the run lasts (/dev/cpu_dma_latency,"
        " best effort, usually needs root): off (default) makes none; hold keeps idle CPUs"
        " polling (0 us; ~5 %% faster lockstep on a quiet 2-core host); US holds that many"
        " microseconds",
    )
