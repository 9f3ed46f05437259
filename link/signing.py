"""MAVLink 2 signing configuration shared by both ends of the link.

With a :class:`Signing`, a session signs every outgoing frame and checks incoming frames against
the same key (see :mod:`link.codec`); the pump side requires signed frames.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

SIGNING_KEY_BYTES = 32


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
    """

    key: bytes
    link_id: int = 0
    require: bool = True

    def __post_init__(self) -> None:
        if len(self.key) != SIGNING_KEY_BYTES:
            raise ValueError(f"signing key: {len(self.key)} bytes, need {SIGNING_KEY_BYTES}")
        if not 0 <= self.link_id <= 255:
            raise ValueError(f"signing link_id: {self.link_id}, allowed 0..255")

    @classmethod
    def from_file(cls, path: str | Path, *, link_id: int = 0, require: bool = True) -> Signing:
        """Load a key file: 32 raw bytes or 64 hexadecimal characters (whitespace ignored).

        Raises
        ------
        ValueError
            Naming the file and what is wrong with it.
        """
        raw = Path(path).read_bytes()
        text = raw.strip()
        key: bytes
        if len(text) == 2 * SIGNING_KEY_BYTES:
            try:
                key = bytes.fromhex(text.decode("ascii"))
            except (UnicodeDecodeError, ValueError):
                key = raw
        else:
            key = raw
        if len(key) != SIGNING_KEY_BYTES:
            raise ValueError(
                f"{path}: signing key has {len(raw)} bytes, need {SIGNING_KEY_BYTES} raw bytes "
                f"or {2 * SIGNING_KEY_BYTES} hex characters"
            )
        return cls(key, link_id, require)

    @classmethod
    def generate(cls, seed: int | None = None, *, link_id: int = 0) -> Signing:
        """A fresh key: random per run (``seed=None``), or derived from ``seed`` (tests, replays)."""
        if seed is None:
            key = os.urandom(SIGNING_KEY_BYTES)
        else:
            key = hashlib.sha256(f"pressor-signing-{seed}".encode()).digest()
        return cls(key, link_id)

    def write(self, path: str | Path) -> Path:
        """Write the key as hex to ``path`` (mode 0600) for the peer process."""
        path = Path(path)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(self.key.hex() + "\n")
        return path
