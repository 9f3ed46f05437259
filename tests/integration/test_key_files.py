"""Key files at the command line: ``pressor run``, ``device`` and ``sil`` read and check the
signing key before any port opens (a bad one is exit 2 and one line naming the file), and warn
(one line each, and in the run's summary) of a key file every user can read or an all-zero key."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pressor.link import Signing
from tests.support.sil_helpers import pressor

#: a port that does not exist: a command that opened it before the key would name it instead
NO_PORT = "/nonexistent/ttyPRESSOR"
#: each command's arguments that get it to the point of opening ``--port``
COMMANDS = {
    "run": ["run", "--controller", "pi", "--port", NO_PORT],
    "device": ["device", "--duration", "10", "--port", NO_PORT],
}


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_bad_key_file_is_refused_naming_the_file_before_the_port_opens(tmp_path, command):
    key = tmp_path / "short.key"
    key.write_text("abcd\n")
    out = pressor(*COMMANDS[command], "--signing-key", str(key), cwd=tmp_path)
    assert out.returncode == 2
    [line] = _lines(out.stderr)
    assert line.startswith(f"pressor {command}: --signing-key") and str(key) in line, line
    assert line.count(str(key)) == 1  # named once
    assert NO_PORT not in line


def test_a_bad_key_file_ends_pressor_sil_before_it_starts_its_device(tmp_path):
    key = tmp_path / "spaced.key"
    key.write_text("0123 4567 89ab cdef xyz\n")  # whitespace is fine, 'xyz' is not hex
    out = pressor("sil", "--controller", "pi", "--signing-key", str(key), cwd=tmp_path)
    assert out.returncode == 2
    [line] = _lines(out.stderr)
    assert line.startswith(f"pressor sil: --signing-key {key}: signing key has 24 bytes"), line
    assert not list(tmp_path.glob("*.rrd")) and not list(tmp_path.glob(".*"))  # nothing started


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_all_zero_key_every_user_can_read_is_warned_one_line_each(tmp_path, command):
    key = Signing(bytes(32)).write(tmp_path / "zero.key")
    key.chmod(0o644)
    out = pressor(*COMMANDS[command], "--signing-key", str(key), cwd=tmp_path)
    *warnings, last = _lines(out.stderr)
    assert out.returncode == 2 and NO_PORT in last  # then the port, which does not exist
    assert len(warnings) == 2, out.stderr
    assert all(w.startswith(f"pressor {command}: warning: signing key {key}:") for w in warnings)
    assert "every user (mode 0644)" in warnings[0] and "are zero" in warnings[1]


def test_a_sil_run_with_a_key_file_every_user_can_read_says_so_in_its_summary(tmp_path: Path):
    key = Signing.generate().write(tmp_path / "shared.key")
    key.chmod(0o644)
    summary = tmp_path / "s.json"
    # the default controller: a baseline's run adds its own warning (not the cautious start)
    out = pressor(
        "sil", "--duration", "5", "--signing-key", str(key),
        "--summary", str(summary), "--rrd", str(tmp_path / "r.rrd"), cwd=tmp_path,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    [line] = _lines(out.stderr)
    assert line.startswith(f"pressor sil: warning: signing key {key}: readable by every user")
    [recorded] = json.loads(summary.read_text())["signing_warnings"]
    assert line.endswith(recorded)
