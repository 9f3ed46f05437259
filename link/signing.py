"""MAVLink 2 signing configuration shared by both ends of the link.

With a :class:`Signing`, a session signs every outgoing frame and checks incoming frames against
the same key (see :mod:`pressor.link.codec`); the pump side requires signed frames.

Timestamps. A key that outlives a run (a key file, or a random per-run key) signs with the wall
clock, as the MAVLink signing rules ask (10 µs units since 2015-01-01 UTC): a receiver starts from
its own wall-clock stamp and refuses a new stream more than a minute behind it, so frames recorded
in an earlier run with the same key are refused. Keys derived from a seed (tests, replays) sign
with the session's run clock instead, so those runs are byte-identical.

Provisioning. ``pressor run`` and ``pressor device`` sign by default with the key file at
:func:`default_key_path` (``$XDG_CONFIG_HOME/pressor/signing.key``, else
``~/.config/pressor/signing.key``), made by ``pressor keygen`` and copied to the other end;
``--signing-key FILE`` names another, ``--no-signing`` turns signing off (with a warning). A key
file readable by every user, or a key of all zeros, loads with a warning
(:func:`key_file_warnings`).
"""

from __future__ import annotations

import hashlib
import os
import stat
import time
from dataclasses import dataclass
from pathlib import Path

SIGNING_KEY_BYTES = 32
#: the MAVLink signing epoch, 2015-01-01 00:00:00 UTC (Unix s)
MAVLINK_EPOCH_UNIX_S = 1420070400


def wall_clock_s() -> float:
    """Seconds since the MAVLink signing epoch (the signing timestamps' wall clock)."""
    return time.time() - MAVLINK_EPOCH_UNIX_S


def key_file_warnings(path: str | Path, key: bytes) -> list[str]:
    """What is unsafe about a key file that loaded (one line each, naming the file): readable by
    every user of the host (anyone there can sign pump commands), or a key of all zero bytes (a
    placeholder, not a secret).

    Parameters
    ----------
    path
        The key file (its mode is read; a file that cannot be stat'ed gives no mode warning).
    key
        The key loaded from it (:meth:`Signing.from_file`).
    """
    out = []
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = 0
    if stat.S_ISREG(mode) and mode & stat.S_IROTH:
        out.append(
            f"signing key {path}: readable by every user (mode {stat.S_IMODE(mode):04o}):"
            f" anyone on this host can sign pump commands; chmod 600 {path}"
        )
    if not any(key):
        out.append(
            f"signing key {path}: all {len(key)} bytes are zero, a placeholder anyone can sign"
            " with; make a real one with 'pressor keygen'"
        )
    return out


def default_key_path() -> Path:
    """Where ``pressor keygen`` writes and ``pressor run`` / ``device`` read the key by default."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "pressor" / "signing.key"


@dataclass(frozen=True, slots=True)
class Signing:
    """MAVLink 2 signing configuration shared by both ends.

    Attributes
    ----------
    key
        32-byte secret.
    link_id
        Link id written in each signature (0-255).
    require
        Refuse unsigned incoming frames (the pump side must; default).
    wall_clock
        Sign with wall-clock timestamps (:func:`wall_clock_s`) instead of the session's run clock.
    """

    key: bytes
    link_id: int = 0
    require: bool = True
    wall_clock: bool = False

    def __post_init__(self) -> None:
        if len(self.key) != SIGNING_KEY_BYTES:
            raise ValueError(f"signing key: {len(self.key)} bytes, need {SIGNING_KEY_BYTES}")
        if not 0 <= self.link_id <= 255:
            raise ValueError(f"signing link_id: {self.link_id}, allowed 0..255")

    @classmethod
    def from_file(cls, path: str | Path, *, link_id: int = 0, require: bool = True) -> Signing:
        """Load a key file: 32 raw bytes or 64 hexadecimal characters (whitespace anywhere in
        them ignored: spaces, tabs, line breaks, as when a key is pasted in groups or lines).

        Raises
        ------
        ValueError
            Naming the file and what is wrong with it.
        """
        raw = Path(path).read_bytes()
        text = b"".join(raw.split())  # every ASCII whitespace byte, not only at the ends
        key = raw
        if len(text) == 2 * SIGNING_KEY_BYTES:
            try:
                key = bytes.fromhex(text.decode("ascii"))
            except (UnicodeDecodeError, ValueError):
                key = raw
        if len(key) != SIGNING_KEY_BYTES:
            raise ValueError(
                f"{path}: signing key has {len(raw)} bytes, need {SIGNING_KEY_BYTES} raw bytes "
                f"or {2 * SIGNING_KEY_BYTES} hex characters"
            )
        return cls(key, link_id, require, wall_clock=True)

    @classmethod
    def generate(cls, seed: int | None = None, *, link_id: int = 0) -> Signing:
        """A fresh key: random per run (``seed=None``, wall-clock timestamps), or derived from
        ``seed`` (tests, replays; run-clock timestamps)."""
        if seed is None:
            return cls(os.urandom(SIGNING_KEY_BYTES), link_id, wall_clock=True)
        key = hashlib.sha256(f"pressor-signing-{seed}".encode()).digest()
        return cls(key, link_id)

    def write(self, path: str | Path, *, exclusive: bool = False) -> Path:
        """Write the key as hex to ``path`` (mode 0600) for the peer process; ``exclusive``:
        never replace an existing file (``FileExistsError``)."""
        path = Path(path)
        flags = os.O_WRONLY | os.O_CREAT | (os.O_EXCL if exclusive else os.O_TRUNC)
        fd = os.open(path, flags, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(self.key.hex() + "\n")
        return path
