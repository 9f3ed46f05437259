"""``pressor run`` and ``pressor faults``: the runtime's own commands.

``pressor run --port DEV`` is the runtime end alone, on a device started by hand (a real cable or
a ``socat`` pty). It parses its options into a :class:`pressor.runtime.inputs.config.RunConfig`, opens the
port, signs the link (``--signing-key``, default the ``pressor keygen`` key), runs the loop
(:func:`pressor.runtime.session.run_runtime`) and prints the summary (:mod:`pressor.runtime.summary`). It
schedules on its own online estimate by default (``--schedule estimated``): a real monitor and pump
send no K, T, τ, and a device that never sends SCHEDULING_PARAMS works; ``--schedule oracle`` needs
a device that sends them. ``pressor run --fault ...`` scores a schedule injected by that device;
the device's scenario is not known here, so the step-window metrics and ``disturbances`` are null.
``pressor run --target-mmhg`` (or ``--target-file``, changed live with it or ``--target-stdin``)
sets the MAP target on the runtime side instead of the device's MAP_TARGET (a line ``ack`` on the
same inputs acknowledges an alarm: HOLD or FAILSAFE resume once the fault cleared); the device's
hello must announce the drug and concentration the controller assumes (``--drug``,
``--concentration-ug-ml``) and a pump that reaches the controller's maximum rate, else the run
refuses the device, telling it why (PRESSOR_REFUSAL), and exits 2 (:mod:`pressor.runtime.inputs.clinician`).
``pressor sil``, which also starts the device, is served by the front door (:mod:`pressor.sil`).

``pressor keygen`` writes a fresh signing key (default :func:`pressor.link.signing.default_key_path`):
``pressor run`` and ``pressor device`` sign the link with it unless ``--no-signing`` (warned).

``pressor faults`` lists the injectable fault kinds (``--fault KIND[:ARGS]``) with their arguments,
defaults, detection bounds and safe states, then what the supervisor detects.

Exit codes: 0 success, 1 the run completed but a check failed (or the device stalled, or the link
failed), 2 bad usage or input (one line on stderr naming the option or file, value and range) or
a refused device hello (one line; the device was sent the same line and a reason code).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pressor.plumbing.usage import UsageError, UsageParser, parse_first, run_command, usage_exit
from pressor.runtime.inputs.clinician import add_clinician_options, clinician_input
from pressor.runtime.inputs.config import (
    DEFAULT_RATE_HZ,
    MAX_RATE_HZ,
    add_run_options,
    positive,
    run_config,
)
from pressor.runtime.inputs.dosing import add_dosing_options


def _run_parser() -> UsageParser:
    p = UsageParser(prog="pressor run", description="the controller runtime alone on a serial port")
    add_run_options(p)
    p.add_argument("--port", required=True, help="device path or pyserial URL")
    p.add_argument(
        "--ticks",
        type=int,
        default=0,
        help="stop after N ticks, one per sample period (default 0: when the device ends)",
    )
    add_clinician_options(p)
    add_dosing_options(p)
    return p


def _main_run(argv: Sequence[str]) -> int:
    from pressor.link import fast_port, open_port
    from pressor.runtime.inputs.config import load_signing
    from pressor.runtime.session import run_runtime, start_run
    from pressor.runtime.summary import finish

    args = _run_parser().parse_args(argv)
    try:
        config = run_config(args, ticks=args.ticks, clinician=clinician_input(args))
    except UsageError as exc:  # the device waiting in its handshake is told too
        _refuse_on_the_wire(args, str(exc))
        raise
    key_warnings: list[str] = []  # a key file every user can read, an all-zero key
    # a bad key: refused before the port opens
    signing = load_signing(config, generate=False, warnings=key_warnings)
    start_run()  # from here a stop signal is graceful: the safe command, the record kept
    try:
        port = fast_port(open_port(args.port))
    except Exception as exc:  # pyserial raises several types for a bad path/URL
        raise UsageError(f"--port {args.port}: cannot open: {exc}") from None
    if signing is None:
        print(
            "pressor run: warning: the link is unsigned (--no-signing): anything on the line"
            " can command the pump",
            file=sys.stderr,
        )
    identity = {
        "controller": config.controller,
        "link": args.port,
        "mode": config.mode,
        "rate_hz": config.rate_hz,
        "signed": signing is not None,
    }
    if key_warnings:  # only then: the summaries of other runs keep their bytes
        identity["signing_warnings"] = key_warnings
    summary, result = run_runtime(port, config, identity, signing)
    return finish(summary, result, config, "pressor run")


def _refuse_on_the_wire(args: Any, text: str, wait_s: float = 3.0) -> None:
    """Tell the device that this run cannot start (docs/PROTOCOL.md, "A refusal before the
    handshake"): open ``--port``, sign as asked, send PRESSOR_REFUSAL ``RUNTIME_CONFIG`` with
    ``text`` and a heartbeat FAULT at once and in answer to each device hello for ``wait_s``
    (s). Best effort: a port or key that cannot be used leaves it unsaid (the one line on stderr
    stands)."""
    import time

    from pressor.link import (
        REFUSAL_RUNTIME_CONFIG,
        HelloRefused,
        LinkError,
        RuntimeSession,
        open_port,
    )
    from pressor.link.signing import Signing, default_key_path

    try:
        key = None if args.no_signing else Signing.from_file(args.signing_key or default_key_path())
        ep = RuntimeSession(open_port(args.port), signing=key)
    except Exception:  # pyserial's and the key file's many errors: nothing can be sent
        return
    refusal = HelloRefused(REFUSAL_RUNTIME_CONFIG, text)
    try:
        ep.refuse(refusal)
        end = time.monotonic() + wait_s
        while (left := end - time.monotonic()) > 0:
            ep.peer_hello = None
            if ep.wait_for_hello(left) is not None:  # a device (re)started: tell it too
                ep.refuse(refusal)
    except (LinkError, OSError):
        pass
    finally:
        ep.close()


def _main_keygen(argv: Sequence[str]) -> int:
    p = UsageParser(
        prog="pressor keygen",
        description="write a fresh 32-byte link signing key (hex, mode 0600) for pressor run and"
        " pressor device; copy the same file to the other end",
    )
    # the default is spelled out rather than computed: pressor.link (pyserial, the dialect) loads
    # only after the arguments parse, so that --help answers at once
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="key file (default: $XDG_CONFIG_HOME/pressor/signing.key, ~/.config when unset)",
    )
    p.add_argument("--force", action="store_true", help="replace an existing key file")
    args = p.parse_args(argv)
    from pressor.link.signing import Signing, default_key_path

    path = args.out or default_key_path()
    if path.exists() and not args.force:
        raise UsageError(f"--out {path}: a key exists already (--force replaces it)")
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    if args.force:
        path.unlink(missing_ok=True)
    Signing.generate().write(path, exclusive=True)
    print(f"signing key: {path}")
    return 0


def _main_faults(argv: Sequence[str]) -> int:
    from pressor.contracts.faults import catalogue_rows
    from pressor.runtime.core.supervisor_bounds import detection_bounds
    from pressor.runtime.core.supervisor_config import DEFAULT_SAMPLE_AGE_LIMIT_S, SupervisorConfig

    p = UsageParser(prog="pressor faults", description="fault kinds the supervisor detects")
    p.add_argument(
        "--rate",
        type=positive("--rate", MAX_RATE_HZ),
        default=DEFAULT_RATE_HZ,
        help="loop rate the detection bounds are given at (Hz)",
    )
    args = p.parse_args(argv)
    period_s = 1.0 / args.rate
    cfg = SupervisorConfig(
        sample_period_s=period_s, stale_after_s=max(DEFAULT_SAMPLE_AGE_LIMIT_S, period_s)
    )
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
    """Entry point for ``pressor run | faults`` (see the module docstring for exit codes)."""
    handlers = {"run": _main_run, "faults": _main_faults, "keygen": _main_keygen}
    if command not in handlers:
        return usage_exit("pressor.runtime.cli", f"unknown command {command!r}")
    if command != "run":  # they open no link and start no loop: nothing for run_guarded to guard
        return run_command(f"pressor {command}", handlers[command], argv)
    # --help and a bad option answer before the link, the recorder and numpy load
    early = parse_first(f"pressor {command}", _run_parser(), argv)
    if early is not None:
        return early
    from pressor.runtime.session import run_guarded

    return run_guarded(f"pressor {command}", handlers[command], argv)
