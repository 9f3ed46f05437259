"""Atomic file output: write a hidden temporary sibling, then move it over the target.

Every file pressor writes whole (recordings, summaries, trial tables, artifacts, generated code)
goes through :class:`AtomicFile` (the ``.tlog``, a log streamed while the patient is on the line,
is written in place instead: :class:`pressor.link.tlog.TlogWriter`): the data goes to ``.NAME.PID.RANDOM.tmp`` in the
target's directory and :func:`os.replace` moves it over ``NAME`` only when the writer succeeds
(atomic on POSIX: a reader sees the old file or the new one, never half of one). A writer that
fails removes its temporary file and leaves an earlier ``NAME`` untouched.

Two forms. A block that writes everything at once::

    with AtomicFile(path) as target, open(target.tmp, "wb") as fh:
        fh.write(data)              # committed when the block ends without an exception

or :func:`write_atomic` for a whole ``str``/``bytes``; a streaming writer that lives across many
calls (the ``.rrd`` recorder) keeps the :class:`AtomicFile` and calls :meth:`AtomicFile.commit`
when it closes.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path
from types import TracebackType


class AtomicFile:
    """A target file written through a hidden temporary sibling.

    Parameters
    ----------
    path
        The target; its directory must exist. Nothing is created until the writer opens
        :attr:`tmp`.

    Attributes
    ----------
    path
        The target.
    tmp
        The temporary sibling to write (``.NAME.PID.RANDOM.tmp``, unique per instance).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.tmp = self.path.with_name(
            f".{self.path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
        )
        self._done = False

    def commit(self) -> Path:
        """Move the temporary file over the target and return the target (idempotent).

        If the move fails the temporary file is removed and the error raised.
        """
        if not self._done:
            self._done = True
            try:
                os.replace(self.tmp, self.path)
            except BaseException:
                self.tmp.unlink(missing_ok=True)
                raise
        return self.path

    def discard(self) -> None:
        """Remove the temporary file; the target stays as it was (idempotent)."""
        if not self._done:
            self._done = True
            self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> AtomicFile:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


def write_atomic(path: str | Path, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` atomically (text as UTF-8, newlines as given); return ``path``.

    Parameters
    ----------
    path
        The target; its directory must exist.
    data
        The whole content.
    """
    with AtomicFile(path) as target:
        if isinstance(data, bytes):
            target.tmp.write_bytes(data)
        else:
            with open(target.tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(data)
    return target.path
