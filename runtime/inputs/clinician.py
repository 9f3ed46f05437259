"""The clinician's input on the runtime side: the MAP target and the syringe the controller assumes.

``pressor run`` takes the target from the device's MAP_TARGET by default. ``--target-mmhg`` (or
``--target-file``) makes it the runtime's own: the device's value is then ignored and MAP_TARGET is
no longer required for a tick. ``--target-file`` and ``--target-stdin`` change it while the loop
runs (:mod:`pressor.runtime.inputs.target_source`), and carry the clinician's acknowledgement (a line
``ack``: HOLD or FAILSAFE resume once the fault cleared, :mod:`pressor.runtime.core.supervisor_io`).
``--drug`` and ``--concentration-ug-ml`` state the drug and concentration in the syringe; they must
match the loaded design's (:mod:`pressor.contracts.drug`: a generated module's ``DRUG`` and
``DRUG_CONCENTRATION_UG_ML``, else phenylephrine at 100 µg/ml) and default to them
(:mod:`pressor.runtime.inputs.dosing` checks them, the drug library and ``--weight-kg``);
A device whose hello does not fit these is refused by :mod:`pressor.runtime.inputs.hello_checks`.
"""

from __future__ import annotations

import argparse
import math
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pressor.contracts.checks import allowed_range, check_range
from pressor.contracts.controller import DESIGN_CONCENTRATION_UG_ML, DESIGN_DRUG
from pressor.contracts.drug import MAX_CONCENTRATION_UG_ML, MAX_DRUG_CHARS
from pressor.plumbing.usage import UsageError

#: MAP targets the runtime accepts (mmHg), from any source
TARGET_MIN_MMHG = 50.0
TARGET_MAX_MMHG = 120.0
#: the line that acknowledges an alarm and asks to resume (stdin, the target file)
ACK_WORD = "ack"


@dataclass(frozen=True)
class ClinicianInput:
    """What ``pressor run`` was told about the target and the syringe (checked).

    Attributes
    ----------
    target_mmhg
        The runtime's starting target (mmHg); ``None``: the device's MAP_TARGET is used.
    target_file
        File re-read whenever it changes (one number, mmHg); ``None``: none.
    target_stdin
        Read a new target from each stdin line while running.
    drug
        Drug in the syringe (lower case); the loaded design's once checked
        (:mod:`pressor.runtime.inputs.dosing`).
    concentration_ug_ml
        Syringe concentration (µg/ml); the loaded design's once checked.
    drug_given, concentration_given
        Whether ``--drug`` / ``--concentration-ug-ml`` were given (else the design's are taken).
    weight_kg
        The patient's weight (kg, ``--weight-kg``), or ``None``.
    dose_limits
        The drug library's limits for this drug, syringe and weight
        (:class:`pressor.runtime.inputs.drug_library.DoseLimits`), set by
        :func:`pressor.runtime.inputs.dosing.bind_syringe`.
    dose_unit
        The unit of the library's limits for this drug (``ug/min`` or ``ug/kg/min``).
    """

    target_mmhg: float | None = None
    target_file: Path | None = None
    target_stdin: bool = False
    drug: str = DESIGN_DRUG
    concentration_ug_ml: float = DESIGN_CONCENTRATION_UG_ML
    drug_given: bool = False
    concentration_given: bool = False
    weight_kg: float | None = None
    dose_limits: Any = None
    dose_unit: str = "ug/min"

    @property
    def target_source(self) -> str:
        """``runtime`` when the runtime sets the target, else ``device``."""
        return "device" if self.target_mmhg is None else "runtime"


def number_in(text: str, lo: float, hi: float, unit: str, *, lo_open: bool = False) -> float:
    """The number ``text`` holds if it lies in [lo, hi] (``lo_open``: (lo, hi]) ``unit``;
    ``ValueError`` naming the text, its value and the allowed range otherwise (NaN included;
    :func:`pressor.contracts.checks.check_range`)."""
    try:
        value = float(text)
    except ValueError:
        allowed = allowed_range(lo, hi, lo_open=lo_open, unit=unit)
        raise ValueError(f"{text.strip()!r}: must be a finite number {allowed}") from None
    return check_range(repr(text.strip()), value, lo, hi, lo_open=lo_open, unit=unit)


def split_ack(text: str) -> tuple[str, bool]:
    """``text`` without its :data:`ACK_WORD` lines, and whether it had one (case and surrounding
    blanks ignored): the clinician's acknowledgement rides on stdin and the target file."""
    lines = text.splitlines()
    rest = [line for line in lines if line.strip().lower() != ACK_WORD]
    return "\n".join(rest), len(rest) < len(lines)


def split_commands(
    text: str, max_rate_ml_h: float
) -> tuple[str, list[tuple[str, float]], list[str]]:
    """The clinician's command lines in ``text`` (case and surrounding blanks ignored): ``stop``
    (0 ml/h now, held), ``manual RATE`` (RATE ml/h in [0, ``max_rate_ml_h``], held), ``resume``
    (back to automatic control).

    Returns
    -------
    tuple
        The text without them (the target and ``ack`` lines), the commands as ``(kind, ml/h)``
        in order, and one refusal line per malformed one (``manual`` without a rate in range).
    """
    rest, commands, refused = [], [], []
    for line in text.splitlines():
        words = line.strip().lower().split()
        if words in (["stop"], ["resume"]):
            commands.append((words[0], 0.0))
        elif words and words[0] == "manual":
            try:
                if len(words) != 2:
                    raise ValueError(f"{line.strip()!r}: give one rate, e.g. 'manual 20'")
                rate = number_in(words[1], 0.0, max_rate_ml_h, "ml/h")
            except ValueError as exc:
                refused.append(f"manual {exc}")
            else:
                commands.append(("manual", rate))
        else:
            rest.append(line)
    return "\n".join(rest), commands, refused


def parse_target(text: str) -> float:
    """A MAP target (mmHg) from ``text``; ``ValueError`` naming the allowed range otherwise."""
    return number_in(text, TARGET_MIN_MMHG, TARGET_MAX_MMHG, "mmHg")


#: the largest clinician's input file read (bytes): a target and a few command lines
MAX_INPUT_FILE_BYTES = 4096
_FILE_KINDS = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
)


def read_input_file(path: Path) -> str:
    """The text of the clinician's input file ``path``, read without ever blocking.

    A FIFO no one writes would block an ``open()`` (and with it the loop's tick, and the stop
    signals it polls), a device file would never end: the file is opened non-blocking and only a
    regular file of at most :data:`MAX_INPUT_FILE_BYTES` bytes is read.

    Raises
    ------
    ValueError
        ``cannot read: CAUSE``, ``not a regular file (a FIFO)`` (or another kind), or a file
        longer than :data:`MAX_INPUT_FILE_BYTES` bytes.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as exc:
        raise ValueError(f"cannot read: {exc.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = next((name for test, name in _FILE_KINDS if test(st.st_mode)), "another kind")
            raise ValueError(f"not a regular file ({kind})")
        if st.st_size > MAX_INPUT_FILE_BYTES:
            raise ValueError(
                f"{st.st_size} bytes: a target file holds a number and command lines, at most"
                f" {MAX_INPUT_FILE_BYTES} bytes"
            )
        data = os.read(fd, MAX_INPUT_FILE_BYTES)
    except OSError as exc:
        raise ValueError(f"cannot read: {exc.strerror}") from None
    finally:
        os.close(fd)
    return data.decode("ascii", "replace")


def read_target_file(path: Path) -> float:
    """The target (mmHg) ``path`` holds (an ``ack`` line in it is not a target); ``ValueError`` if
    it cannot be read (:func:`read_input_file`) or is out of range."""
    return parse_target(split_commands(split_ack(read_input_file(path))[0], math.inf)[0])


def argtype(name: str, parse: Any) -> Any:
    """An argparse type for option ``name`` from a parser raising ``ValueError``."""

    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{name} {exc}") from None

    return convert


def parse_concentration(text: str) -> float:
    """A concentration (µg/ml) from ``text``; ``ValueError`` naming the allowed range otherwise."""
    return number_in(text, 0.0, MAX_CONCENTRATION_UG_ML, "ug/ml", lo_open=True)


def parse_drug(text: str) -> str:
    """A drug name (lower case, 1-16 ASCII characters); ``ValueError`` otherwise."""
    name = text.strip().lower()
    if not (name and name.isascii() and len(name) <= MAX_DRUG_CHARS):
        raise ValueError(f"{text!r}: allowed 1 to {MAX_DRUG_CHARS} ASCII characters")
    return name


#: what ``--target-mmhg`` means for ``pressor run``
RUN_TARGET_HELP = (
    "the runtime's own MAP target (mmHg, {rng}); the device's MAP_TARGET is then ignored and not"
    " required (default: the device's MAP_TARGET)"
)
#: what ``--drug`` and ``--concentration-ug-ml`` mean for ``pressor run``
RUN_DRUG_HELP = (
    "drug in the syringe: must be the loaded design's, and the device's hello must announce the"
    f" same (default: the design's; the shipped one's is {DESIGN_DRUG})"
)
RUN_CONCENTRATION_HELP = (
    "syringe concentration (ug/ml): must be the one whose ml/h the design's gain K (mmHg per ml/h)"
    " counts, and the device's hello must announce the same (default: the design's; the shipped"
    f" one's is {DESIGN_CONCENTRATION_UG_ML:g})"
)


def target_range_text() -> str:
    """``allowed [50, 120]``: the MAP targets accepted from any source (mmHg)."""
    return f"allowed [{TARGET_MIN_MMHG:g}, {TARGET_MAX_MMHG:g}]"


def add_target_option(p: argparse.ArgumentParser, help_text: str = RUN_TARGET_HELP) -> None:
    """Add ``--target-mmhg MMHG`` (a MAP target in [50, 120] mmHg, default ``None``) to ``p``;
    ``{rng}`` in ``help_text`` reads the allowed range."""
    p.add_argument(
        "--target-mmhg",
        type=argtype("--target-mmhg", parse_target),
        default=None,
        metavar="MMHG",
        help=help_text.format(rng=target_range_text()),
    )


def add_syringe_options(
    p: argparse.ArgumentParser,
    drug_help: str = RUN_DRUG_HELP,
    concentration_help: str = RUN_CONCENTRATION_HELP,
) -> None:
    """Add ``--drug`` and ``--concentration-ug-ml`` (checked names and µg/ml, default ``None``)
    to ``p``."""
    p.add_argument("--drug", type=argtype("--drug", parse_drug), default=None, help=drug_help)
    p.add_argument(
        "--concentration-ug-ml",
        type=argtype("--concentration-ug-ml", parse_concentration),
        default=None,
        metavar="UG_ML",
        help=concentration_help,
    )


def add_clinician_options(p: argparse.ArgumentParser) -> None:
    """Add ``--target-mmhg``, ``--target-file``, ``--target-stdin``, ``--drug`` and
    ``--concentration-ug-ml`` to ``p`` (``pressor run``)."""
    rng = target_range_text()
    add_target_option(p)
    p.add_argument(
        "--target-file",
        type=Path,
        default=None,
        metavar="FILE",
        help=f"a file holding one number, the MAP target (mmHg, {rng}): read at start (the"
        " starting target, instead of --target-mmhg) and again whenever it changes; a bad value"
        " is refused with one line on stderr and the target kept; a line 'ack' in it"
        " acknowledges an alarm and resumes automatic control once the fault cleared"
        " (default: none)",
    )
    p.add_argument(
        "--target-stdin",
        action="store_true",
        help=f"read a new MAP target (mmHg, {rng}) from each line on stdin while running, or"
        " 'ack' to acknowledge an alarm and resume automatic control once the fault cleared, or"
        " 'stop' (0 ml/h now, held), 'manual RATE' (ml/h, held), 'resume' (back to automatic"
        " control; the same lines work in --target-file); needs --target-mmhg or --target-file"
        " for the starting target (default: off)",
    )
    add_syringe_options(p)


def clinician_input(args: argparse.Namespace) -> ClinicianInput:
    """Check the options :func:`add_clinician_options` parsed into a :class:`ClinicianInput`.

    Raises
    ------
    pressor.plumbing.usage.UsageError
        Both ``--target-mmhg`` and ``--target-file``; ``--target-stdin`` without a starting
        target; a target file that cannot be read or holds no valid target.
    """
    target = args.target_mmhg
    if args.target_file is not None:
        if target is not None:
            raise UsageError(
                "--target-mmhg and --target-file: choose one (the file holds the starting target)"
            )
        try:
            target = read_target_file(args.target_file)
        except ValueError as exc:
            raise UsageError(f"--target-file {args.target_file}: {exc}") from None
    if args.target_stdin and target is None:
        raise UsageError("--target-stdin: needs a starting target (--target-mmhg or --target-file)")
    return ClinicianInput(
        target_mmhg=target,
        target_file=args.target_file,
        target_stdin=args.target_stdin,
        drug=DESIGN_DRUG if args.drug is None else args.drug,
        concentration_ug_ml=(
            DESIGN_CONCENTRATION_UG_ML
            if args.concentration_ug_ml is None
            else args.concentration_ug_ml
        ),
        drug_given=args.drug is not None,
        concentration_given=args.concentration_ug_ml is not None,
        weight_kg=getattr(args, "weight_kg", None),
    )


def describe_target(record: dict[str, Any]) -> str:
    """One terminal line for the summary's ``target`` record (its source, changes, refusals)."""
    if record["source"] == "device":
        return "target: the device's MAP_TARGET"
    text = f"target: the runtime's, {record['initial_mmhg']:g} mmHg"
    for c in record["changes"]:
        text += f"; at {c['sim_time_s']:g} s {c['old_mmhg']:g} -> {c['new_mmhg']:g} mmHg"
    if record["refused"]:
        text += f"; {record['refused']} refused"
    for a in record.get("acks", ()):
        text += f"; ack at {a['sim_time_s']:g} s {'accepted' if a['accepted'] else 'not taken'}"
    return text
