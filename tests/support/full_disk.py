"""A real full disk for the writer tests: a small tmpfs mounted for the test.

:func:`small_tmpfs` mounts a tmpfs of ``size_kib`` KiB on a fresh directory (root, or a user
allowed to mount) and unmounts it afterwards; where nothing can be mounted it falls back to
``/dev/full``, which fails every write with ENOSPC as a full disk does (the test then names its
output files inside a directory of symbolic links to it). Each test says which one it got.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def small_tmpfs(where: Path, size_kib: int = 1024) -> Iterator[tuple[Path, str]]:
    """A directory on a tmpfs of ``size_kib`` KiB, and ``"tmpfs"``; or, where mounting is not
    allowed, a directory whose files ``run.tlog``, ``run.rrd`` and ``s.json`` are links to
    ``/dev/full``, and ``"/dev/full"``."""
    where.mkdir(parents=True, exist_ok=True)
    mounted = (
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs", str(where)],
            capture_output=True,
        ).returncode
        == 0
    )
    if not mounted:
        for name in ("run.tlog", "run.rrd", "s.json"):
            (where / name).symlink_to("/dev/full")
    try:
        yield where, "tmpfs" if mounted else "/dev/full"
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(where)], capture_output=True)


def fill(directory: Path, leave_bytes: int) -> None:
    """Fill the filesystem of ``directory`` until about ``leave_bytes`` are left free."""
    import os

    st = os.statvfs(directory)
    free = st.f_bavail * st.f_frsize
    if free > leave_bytes:
        (directory / "filler").write_bytes(b"\0" * (free - leave_bytes))
