"""Atomic file output (pressor.plumbing.files): the target changes only when the writer succeeds."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from pressor.plumbing.files import AtomicFile, write_atomic


def _leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.startswith("."))


def test_write_atomic_replaces_the_target_and_leaves_no_temporary_file(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old\n")
    assert write_atomic(target, "new\r\nline\n") == target
    assert target.read_bytes() == b"new\r\nline\n"  # text written exactly, newlines as given
    write_atomic(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01"
    assert _leftovers(tmp_path) == []


def test_a_failing_writer_keeps_the_old_target_and_removes_its_temporary_file(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("earlier run\n")
    with pytest.raises(RuntimeError), AtomicFile(target) as out:
        out.tmp.write_text("half a file")
        raise RuntimeError("writer failed")
    assert target.read_text() == "earlier run\n"
    assert _leftovers(tmp_path) == []


def test_a_streaming_writer_commits_or_discards_when_it_closes(tmp_path):
    target = tmp_path / "run.tlog"
    kept = AtomicFile(target)
    with open(kept.tmp, "wb") as fh:
        fh.write(b"frames")
        assert kept.tmp.parent == tmp_path and kept.tmp.name.startswith(".run.tlog.")
        assert not target.exists()  # nothing at the target while the writer runs
    assert kept.commit() == target and kept.commit() == target  # idempotent
    assert target.read_bytes() == b"frames"
    dropped = AtomicFile(target)
    dropped.tmp.write_bytes(b"failed run")
    dropped.discard()
    dropped.discard()
    assert target.read_bytes() == b"frames"
    assert _leftovers(tmp_path) == []


def test_a_failed_move_removes_the_temporary_file(tmp_path):
    target = tmp_path / "busy"
    target.mkdir()  # a directory cannot be replaced by a file
    out = AtomicFile(target)
    out.tmp.write_text("x")
    with pytest.raises(OSError):
        out.commit()
    assert not out.tmp.exists()


def test_two_writers_of_one_target_use_different_temporary_files(tmp_path):
    assert AtomicFile(tmp_path / "a").tmp != AtomicFile(tmp_path / "a").tmp


def test_written_files_get_the_usual_permissions_not_private_ones(tmp_path):
    umask = os.umask(0o022)
    try:
        path = write_atomic(tmp_path / "summary.json", "{}\n")
    finally:
        os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
