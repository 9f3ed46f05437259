"""The rerun recorder writes a real .rrd that reads back with every tick of every channel."""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

os.environ.setdefault("CI", "1")  # the rerun CLI writes analytics files otherwise

from rerun.chunk import RrdReader  # noqa: E402

from pressor.runtime.record.blueprint import EVENTS_ENTITY  # noqa: E402
from pressor.runtime.record.recorder import CHANNEL_INDEX, CHANNELS, Recorder  # noqa: E402
from tests.support.full_disk import fill, small_tmpfs  # noqa: E402


def read_columns(path) -> dict[str, dict[int, float]]:
    """entity -> {tick: value} for every Scalars column in the file, plus event texts."""
    out: dict[str, dict[int, float]] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "tick" not in names:
            continue
        ticks = batch.column("tick").to_pylist()
        if "Scalars:scalars" in names:
            vals = [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
        elif "TextLog:text" in names:
            vals = [v[0] for v in batch.column("TextLog:text").to_pylist()]
        else:
            continue
        out.setdefault(str(chunk.entity_path), {}).update(zip(ticks, vals, strict=True))
    return out


def make_row(k: int) -> list[float]:
    row = [math.nan] * len(CHANNELS)
    row[CHANNEL_INDEX["/patient/map_mmhg"]] = 60.0 + 0.01 * k
    row[CHANNEL_INDEX["/controller/target_mmhg"]] = 80.0
    row[CHANNEL_INDEX["/pump/command_ml_h"]] = float(k % 120)
    return row


def test_recording_holds_map_target_and_infusion_for_every_tick_across_chunk_flushes(tmp_path):
    path = tmp_path / "run.rrd"
    n = 1000  # > 2 chunks of 400
    with Recorder(path, run_label="test", chunk_ticks=400) as rec:
        for k in range(n):
            rec.record(k, 0.1 * k, make_row(k))
        rec.event(500, 50.0, "AUTO -> HOLD: MAP_NAN")
    cols = read_columns(path)
    map_col = cols["/patient/map_mmhg"]
    assert sorted(map_col) == list(range(n))
    assert map_col[777] == pytest.approx(60.0 + 7.77)
    assert set(cols["/controller/target_mmhg"].values()) == {80.0}
    assert cols["/pump/command_ml_h"][250] == 10.0
    assert cols[EVENTS_ENTITY] == {500: "AUTO -> HOLD: MAP_NAN"}
    assert math.isnan(cols["/schedule/K"][3])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # temp file renamed


def test_sim_time_timeline_is_a_duration_in_seconds(tmp_path):
    path = tmp_path / "t.rrd"
    with Recorder(path, run_label="t", chunk_ticks=16) as rec:
        for k in range(20):
            rec.record(k, 0.1 * k, make_row(k))
    for chunk in RrdReader(str(path)).stream().to_chunks():
        batch = chunk.to_record_batch()
        if str(chunk.entity_path) == "/patient/map_mmhg" and "sim_time" in batch.schema.names:
            col = batch.column("sim_time")
            assert "duration" in str(col.type)
            ns = np.asarray(col.cast("int64"))
            ticks = np.asarray(batch.column("tick"))
            assert np.array_equal(ns, np.round(ticks * 0.1 * 1e9).astype(np.int64))
            break
    else:
        pytest.fail("no sim_time column on /patient/map_mmhg")


def test_a_failed_run_keeps_its_recording_up_to_the_failure(tmp_path):
    path = tmp_path / "keep.rrd"
    path.write_bytes(b"previous recording")
    with pytest.raises(RuntimeError):
        with Recorder(path, run_label="x") as rec:
            for k in range(3):
                rec.record(k, 0.1 * k, make_row(k))
            raise RuntimeError("device died")
    assert sorted(read_columns(path)["/patient/map_mmhg"]) == [0, 1, 2]
    assert [p.name for p in tmp_path.iterdir()] == ["keep.rrd"]  # no temporary file left


def test_a_full_disk_stops_the_recording_without_raising(tmp_path):
    """rerun's file sink on a disk that fills under it (a 2 MiB tmpfs filled once the recording
    started; skipped where none can be mounted): the recorder keeps taking rows and events,
    names the failure within a second or two, and still closes."""
    with small_tmpfs(tmp_path / "disk", 2048) as (disk, kind):
        if kind != "tmpfs":
            pytest.skip("no tmpfs can be mounted here")
        rec = Recorder(disk / "x.rrd", run_label="full", chunk_ticks=16)
        fill(disk, 0)
        k = 0
        deadline = time.monotonic() + 30.0
        while rec.error is None and time.monotonic() < deadline:
            for _ in range(500):
                rec.record(k, 0.1 * k, make_row(k))
                k += 1
            rec.event(k, 0.1 * k, "tick")
            time.sleep(0.05)
        rec.close()
        assert rec.error is not None and "x.rrd" in rec.error, k


def test_a_disk_without_room_to_start_a_recording_is_refused_naming_it(tmp_path):
    with small_tmpfs(tmp_path / "disk", 256) as (disk, kind):
        if kind != "tmpfs":
            pytest.skip("no tmpfs can be mounted here")
        with pytest.raises(OSError, match="256 KiB free on its disk"):
            Recorder(disk / "x.rrd", run_label="none")
