"""Every command's ``--help``: each option shows its default (or that it is required) and a
numeric option its unit."""

from __future__ import annotations

import re

import pytest

from pressor import cli

#: commands with options (``scenarios`` takes none)
COMMANDS = ("sil", "run", "device", "trial", "synth", "verify", "codegen", "faults")
#: a number's unit, or what it counts
UNIT = re.compile(
    r"\b(s|Hz|us|ml/h|mmHg)\b|\bcount\b|\bticks\b|\bseed\b|dimensionless|cohort size|processes"
)


def option_blocks(help_text: str) -> dict[str, str]:
    """Option name -> its help text (continuation lines joined), from argparse's help."""
    blocks: dict[str, str] = {}
    name = None
    in_options = False
    for line in help_text.splitlines():
        if line.startswith("options:"):
            in_options = True
            continue
        if not in_options:
            continue
        m = re.match(r"  (-\S+?)[ ,]", line + " ")
        if m:
            name = m.group(1)
            blocks[name] = line
        elif name is not None:
            blocks[name] += " " + line.strip()
    return blocks


@pytest.mark.parametrize("command", COMMANDS)
def test_every_option_help_shows_its_default_and_numbers_their_unit(command, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    assert cli.main([command, "--help"]) == 0
    blocks = option_blocks(capsys.readouterr().out)
    blocks.pop("-h")
    assert blocks, command
    for name, text in blocks.items():
        text = re.sub(r"\s+", " ", text)
        assert re.search(r"\bdefault\b|\(required\)", text), f"pressor {command} {name}: {text}"
        if re.search(r"\(default: -?[0-9.]+\)", text):
            assert UNIT.search(text), f"pressor {command} {name} has no unit: {text}"


def test_a_flag_reads_off_and_a_valueless_option_none(capsys):
    assert cli.main(["sil", "--help"]) == 0
    blocks = {k: re.sub(r"\s+", " ", v) for k, v in option_blocks(capsys.readouterr().out).items()}
    assert "(default: off)" in blocks["--realtime"]
    assert "(default: none)" in blocks["--fault"] and "(default: none)" in blocks["--tlog"]
    assert "(default: 1)" in blocks["--patient-seed"]
