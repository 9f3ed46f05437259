"""Regenerate the committed Python module of the pressor MAVLink dialect.

Run ``python -m pressor.link.generate`` after editing ``link/pressor.xml``; it rewrites
``link/dialect/pressor.py`` with pymavlink's mavgen (wire protocol 2.0, Python 3, XML
validation on). ``tests/link/test_dialect.py`` regenerates into a temporary directory and fails
when the committed module and the XML disagree.

Why wire protocol 2.0 explicitly: mavgen's ``Opts`` defaults to 1.0 and then silently drops every
message with an id above 255 - i.e. all of ours.
"""

from __future__ import annotations

import argparse
import contextlib
import io
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The dialect definition (source of truth).
XML_PATH = HERE / "pressor.xml"
#: The committed generated module.
MODULE_PATH = HERE / "dialect" / "pressor.py"


def generate(xml_path: Path = XML_PATH, out_path: Path = MODULE_PATH) -> Path:
    """Generate the Python dialect module for ``xml_path`` at ``out_path``.

    Parameters
    ----------
    xml_path
        The dialect XML.
    out_path
        Where to write the module (a ``.py`` file; its directory is created).

    Returns
    -------
    Path
        ``out_path``.

    Raises
    ------
    RuntimeError
        When mavgen rejects the XML (it raises ``SystemExit`` on invalid XML).
    """
    from pymavlink.generator import mavgen, mavparse

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    opts = mavgen.Opts(
        str(out_path),
        wire_protocol=mavparse.PROTOCOL_2_0,
        language="Python3",
        validate=True,
        strict_units=False,
    )
    log = io.StringIO()
    try:
        with contextlib.redirect_stdout(log):
            ok = mavgen.mavgen(opts, [str(xml_path)])
    except SystemExit as exc:  # mavgen exits on invalid XML
        raise RuntimeError(f"{xml_path}: mavgen rejected the dialect: {log.getvalue()}") from exc
    if ok is False or not out_path.exists():
        raise RuntimeError(f"{xml_path}: mavgen produced no module: {log.getvalue()}")
    return out_path


def main(argv: list[str] | None = None) -> int:
    """Command line: regenerate the committed module (or write it elsewhere with ``--out``)."""
    parser = argparse.ArgumentParser(prog="python -m pressor.link.generate", description=__doc__)
    parser.add_argument("--xml", type=Path, default=XML_PATH, help="dialect XML")
    parser.add_argument("--out", type=Path, default=MODULE_PATH, help="generated module path")
    args = parser.parse_args(argv)
    path = generate(args.xml, args.out)
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
