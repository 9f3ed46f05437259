"""The rerun recorder: every loop signal to an ``.rrd`` file, batched off the hot path.

Per tick the loop calls :meth:`Recorder.record_tick` with the closed-loop core's
:class:`~pressor.runtime.core.closed_loop.TickRecord` (or :meth:`Recorder.record` with one float per
channel); the row goes into a preallocated ``float64`` array (``chunk_ticks`` rows). When the array
is full — and at :meth:`Recorder.close` — each channel is sent as one column with ``send_columns``
on two timelines, ``tick`` (sequence) and ``sim_time`` (duration, s). ``log()`` costs ~30 µs a call
and ``send_columns`` ~0.3 µs a scalar (docs/PLATFORM-NOTES.md), so a 15-channel tick costs about a
microsecond amortised. Rare events (supervisor transitions, alarms, event markers) are logged one
by one: ``/safety/events`` and ``/events/log`` as ``TextLog``.

Reproducibility: the wall-clock ``log_time`` and ``log_tick`` timelines are disabled, recording
properties (which carry the wall-clock start time) are not sent, and the recording id is derived from
the run's label, so two runs with the same seed log the same values on the same timelines.

With ``live`` (``--view``) the same recording also streams to a viewer as the run goes
(:mod:`pressor.runtime.record.live`; without a file for a ``pressor run --view`` without ``--rrd``):
a viewer that goes away stops its copy only.

The file is written to a hidden temporary name next to the target and renamed on :meth:`close`,
whether the run succeeded or failed (:meth:`abort` keeps it too): the record of a run that went
wrong is kept. Buffered rows go to rerun at least once a second of wall time. A writer failure
(rerun's file sink on a full disk) never reaches the loop: the recording stops there and
:attr:`Recorder.error` says why (the loop's advisory ``RECORD_ERROR``).

Entities (units in the names): see :data:`CHANNELS`; besides them, the design box of a scheduled
controller (:meth:`Recorder.use_controller`, two points per bound: first and last tick), markers on
the MAP plot where a disturbance or fault starts (:meth:`Recorder.plan_markers`) and on the safety
plot at each supervisor transition. The viewer's layout is
:func:`pressor.runtime.record.blueprint.default_blueprint` (docs/VIEWER.md).
"""

from __future__ import annotations

import errno
import math
import os
import threading
import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from pressor.contracts.checks import check_int_range
from pressor.contracts.controller import Controller
from pressor.plumbing.files import AtomicFile
from pressor.runtime.core.closed_loop import TickRecord
from pressor.runtime.core.supervisor_config import sched_limits_of
from pressor.runtime.record.blueprint import (
    BOX_COLOR,
    BOX_ENTITIES,
    DISTURBANCE_MARKERS,
    EVENTS_ENTITY,
    FAULT_MARKERS,
    MARKERS_LOG,
    SERIES_COLORS,
    TRANSITION_MARKERS,
    default_blueprint,
)
from pressor.runtime.record.channels import CHANNEL_INDEX, CHANNELS, record_schedule
from pressor.runtime.record.live import LiveStream, Tee, new_stream

#: free space (bytes) the recording needs on its disk to start
MIN_FREE_BYTES = 1 << 20
_NO_RHO = (math.nan, math.nan, math.nan)


# the channels are re-exported from their old home
__all__ = ["CHANNELS", "CHANNEL_INDEX", "MIN_FREE_BYTES", "Recorder"]


class Recorder:
    """Buffered ``.rrd`` writer for the loop.

    Parameters
    ----------
    path
        Target ``.rrd`` file; its directory must exist. Written only on :meth:`close`. ``None``:
        no file (then ``live`` is required).
    run_label
        Text identifying the run (controller, scenario, seed, ...): the recording id is derived
        from it (UUID v5) so identical runs get identical ids.
    chunk_ticks
        Rows buffered before a flush, in [16, 1_000_000].
    dose_view
        Open the viewer with the dose plot (``pressor run``:
        :func:`pressor.runtime.inputs.dosing.log_dose_series` adds its series).
    live
        A viewer's gRPC URL (:func:`pressor.runtime.shell.viewer.start_viewer`) to stream the
        recording to as well, with the same layout; ``None``: the file only.
    """

    def __init__(
        self,
        path: str | Path | None,
        run_label: str,
        chunk_ticks: int = 4096,
        dose_view: bool = False,
        live: str | None = None,
    ) -> None:
        check_int_range("chunk_ticks", chunk_ticks, 16, 1_000_000)
        if path is None and live is None:
            raise ValueError("a recording needs a file, a viewer or both")
        rid = uuid.uuid5(uuid.NAMESPACE_URL, f"pressor:{run_label}")
        blueprint = default_blueprint(dose_view)
        self._file: rr.RecordingStream | None = None
        self._target: AtomicFile | None = None
        self.path = None if path is None else self._open_file(Path(path), rid, blueprint)
        # with a viewer, two streams: its failure must not read as the file's (live.py); the
        # viewer's has an id of its own, so that a run repeated into a viewer still showing the
        # first one (reused by --view) opens beside it rather than adding ticks to it
        live_stream = None if live is None else LiveStream(live, uuid.uuid4(), blueprint)
        self._rec: Any = self._file if live_stream is None else Tee(self._file, live_stream)
        self._rec.send_recording_name(run_label)
        self._log_styles()
        self._box: tuple[tuple[float, float], ...] | None = None
        self._rho_of: Any = None
        self._markers: list[tuple[float, str, str]] = []
        self._first_tick: tuple[int, float] | None = None
        self._last_tick: tuple[int, float] | None = None
        self._ticks = np.zeros(chunk_ticks, dtype=np.int64)
        self._times = np.zeros(chunk_ticks, dtype=np.float64)
        self._values = np.full((chunk_ticks, len(CHANNELS)), math.nan, dtype=np.float64)
        self._n = 0
        self._row = [math.nan] * len(CHANNELS)
        self.rows_written = 0
        self._closed = False
        #: why the recording stopped (a full disk, an I/O error: the file and the cause), else
        #: None; the loop raises its advisory RECORD_ERROR on it while control goes on
        self.error: str | None = None
        self._sent_at = time.monotonic()
        self._stop = threading.Event()
        self._watch = threading.Thread(target=self._watch_sink, name="rrd sink", daemon=True)
        self._watch.start()

    def _open_file(self, path: Path, rid: uuid.UUID, blueprint: Any) -> Path:
        """Start the file's stream (:attr:`_file`) on a temporary name next to ``path``; return
        ``path``."""
        if not path.parent.is_dir():
            raise FileNotFoundError(f"{path}: directory {path.parent} does not exist")
        st = os.statvfs(path.parent)
        if st.f_bavail * st.f_frsize < MIN_FREE_BYTES:
            # rerun's save() can block for good on a disk that fills while it writes its header
            raise OSError(
                errno.ENOSPC,
                f"{st.f_bavail * st.f_frsize >> 10} KiB free on its disk, the recording needs"
                f" {MIN_FREE_BYTES >> 10} KiB to start",
            )
        self._target = AtomicFile(path)
        self._file = new_stream(rid)
        self._file.save(str(self._target.tmp), default_blueprint=blueprint)
        return path

    def _log_styles(self) -> None:
        """Each channel's and marker's static series style: its legend label and colour."""
        for entity, label in CHANNELS:
            self._rec.log(
                entity, rr.SeriesLines(names=label, colors=SERIES_COLORS.get(entity)), static=True
            )
        for entity, label in (
            (DISTURBANCE_MARKERS, "disturbance starts"),
            (FAULT_MARKERS, "fault starts"),
            (TRANSITION_MARKERS, "supervisor transition"),
        ):
            style = rr.SeriesPoints(names=label, colors=SERIES_COLORS[entity], marker_sizes=6.0)
            self._rec.log(entity, style, static=True)

    @property
    def viewer_lost(self) -> str | None:
        """Why the live view stopped receiving (its viewer closed), else ``None`` (also without
        one); the file goes on regardless."""
        return self._rec.live.lost if isinstance(self._rec, Tee) else None

    def use_controller(self, controller: Controller) -> None:
        """Record what ``controller`` declares: its design box (``/schedule/box/*``) and the K, T, τ
        it scheduled on after its own clamp and rate limit (``/controller/rho/*``: its
        ``scheduled_rho()``, or for a generated LPV module the last three values of its
        ``state()``). Call before the first tick; other controllers leave those channels NaN."""
        self._box = sched_limits_of(controller)[0]
        scheduled_rho, state = (getattr(controller, n, None) for n in ("scheduled_rho", "state"))
        if callable(scheduled_rho):
            self._rho_of = scheduled_rho
        elif self._box is not None and callable(state):
            self._rho_of = lambda: state()[-3:]
        else:
            self._rho_of = None
        if self._box is not None:
            for lo_entity, hi_entity in BOX_ENTITIES:
                for entity, side in ((lo_entity, "low"), (hi_entity, "high")):
                    style = rr.SeriesLines(names=f"design box {side}", colors=BOX_COLOR)
                    self._rec.log(entity, style, static=True)

    def plan_markers(self, markers: Sequence[tuple[float, str, str]]) -> None:
        """Mark events on the MAP plot when the run reaches them.

        Parameters
        ----------
        markers
            ``(start_s, kind, text)``: sim time (s), ``disturbance`` or ``fault``, and the text
            logged to ``/events/log``. The marker sits on the measured MAP of the first tick at or
            after ``start_s`` (on the target when MAP is missing).
        """
        self._markers = sorted(markers, reverse=True)

    def record(self, tick: int, sim_time_s: float, values: Sequence[float]) -> None:
        """Buffer one tick: ``values`` in :data:`CHANNELS` order (NaN for "not available")."""
        if self._first_tick is None:
            self._first_tick = (tick, sim_time_s)
            self._guarded(self._log_box, tick, sim_time_s)
        self._last_tick = (tick, sim_time_s)
        if self._markers and self._markers[-1][0] <= sim_time_s:
            self._guarded(self._log_markers, tick, sim_time_s, values)
        n = self._n
        self._ticks[n] = tick
        self._times[n] = sim_time_s
        self._values[n] = values
        self._n = n + 1
        # at least once a second of wall time, so that a run that ends badly loses at most that
        if self._n == self._ticks.shape[0] or time.monotonic() - self._sent_at >= 1.0:
            self.flush()

    def record_tick(
        self,
        rec: TickRecord,
        map_mmhg: float,
        pump: Any,
        bad_frames: int,
        exec_s: float,
        lateness_s: float,
    ) -> None:
        """Buffer one tick of the loop.

        Parameters
        ----------
        rec
            The closed-loop core's record of the tick.
        map_mmhg
            MAP as recorded (mmHg; NaN on a silent tick).
        pump
            Newest pump status (``delivered_ml_h``, ``volume_ml``), ``None`` before the first.
        bad_frames
            Frames the link refused so far (bad CRC, refused signatures, resyncs).
        exec_s, lateness_s
            The tick's execution time and release lateness (s).
        """
        inp, out = rec.inputs, rec.supervisor
        row = self._row
        ix = CHANNEL_INDEX
        row[ix["/patient/map_mmhg"]] = map_mmhg
        row[ix["/controller/target_mmhg"]] = inp.target_mmhg
        row[ix["/controller/command_ml_h"]] = rec.controller_ml_h
        row[ix["/pump/command_ml_h"]] = out.command_ml_h
        row[ix["/pump/rate_ml_h"]] = pump.delivered_ml_h if pump is not None else math.nan
        row[ix["/pump/volume_ml"]] = pump.volume_ml if pump is not None else math.nan
        row[ix["/schedule/K"]] = inp.K
        row[ix["/schedule/T_s"]] = inp.T_s
        row[ix["/schedule/tau_s"]] = inp.tau_s
        stepped = self._rho_of is not None and rec.controller_ml_h == rec.controller_ml_h
        used = self._rho_of() if stepped else _NO_RHO  # NaN: controller not stepped
        row[ix["/controller/rho/K"]] = used[0]
        row[ix["/controller/rho/T_s"]] = used[1]
        row[ix["/controller/rho/tau_s"]] = used[2]
        row[ix["/loop/exec_us"]] = exec_s * 1e6
        row[ix["/loop/lateness_us"]] = lateness_s * 1e6
        row[ix["/safety/state"]] = float(out.state)
        row[ix["/safety/faults"]] = float(out.faults)
        row[ix["/safety/alarm"]] = 1.0 if out.alarm else 0.0
        row[ix["/link/bad_frames"]] = float(bad_frames)
        record_schedule(rec, row)
        self.record(inp.tick, inp.sim_time_s, row)

    def event(
        self, tick: int, sim_time_s: float, text: str, warn: bool = True, state: int | None = None
    ) -> None:
        """Log a supervisor transition or alarm to ``/safety/events`` (rare; not batched); a
        transition (``state``: the new state) is also marked on the safety plot. Never raises."""
        if self.error is not None:
            return
        try:
            self._at(tick, sim_time_s)
            level = rr.TextLogLevel.WARN if warn else rr.TextLogLevel.INFO
            self._rec.log(EVENTS_ENTITY, rr.TextLog(text, level=level))
            if state is not None:
                self._rec.log(TRANSITION_MARKERS, rr.Scalars(float(state)))
        except (RuntimeError, OSError) as exc:
            self._fail(exc)

    def _log_markers(self, tick: int, sim_time_s: float, values: Sequence[float]) -> None:
        """Log every planned marker due by ``sim_time_s`` on this tick's MAP (else target)."""
        y = values[CHANNEL_INDEX["/patient/map_mmhg"]]
        if y != y:
            y = values[CHANNEL_INDEX["/controller/target_mmhg"]]
        self._at(tick, sim_time_s)
        markers = self._markers
        while markers and markers[-1][0] <= sim_time_s:
            _, kind, text = markers.pop()
            entity = DISTURBANCE_MARKERS if kind == "disturbance" else FAULT_MARKERS
            self._rec.log(entity, rr.Scalars(y))
            self._rec.log(MARKERS_LOG, rr.TextLog(text, level=rr.TextLogLevel.INFO))

    def _at(self, tick: int, sim_time_s: float) -> None:
        self._rec.set_time("tick", sequence=tick)
        self._rec.set_time("sim_time", duration=sim_time_s)

    def _log_box(self, tick: int, sim_time_s: float) -> None:
        """Log the design box's bounds at this tick (the first and the last of the run)."""
        if self._box is None:
            return
        self._at(tick, sim_time_s)
        for (lo, hi), (lo_entity, hi_entity) in zip(self._box, BOX_ENTITIES, strict=True):
            self._rec.log(lo_entity, rr.Scalars(lo))
            self._rec.log(hi_entity, rr.Scalars(hi))

    def _watch_sink(self) -> None:
        """Once a second, off the loop's thread, wait for rerun to write what it was given: its
        file sink reports a write failure (a full disk) only to a flush, as a ``RuntimeError``
        other than a timeout (a slow disk)."""
        while not self._stop.wait(1.0) and self.error is None:
            try:
                self._rec.flush(timeout_sec=5.0)
            except RuntimeError as exc:
                if "timed out" not in str(exc):
                    self._fail(exc)

    def _guarded(self, log: Any, *args: Any) -> None:
        """Call ``log(*args)`` unless the recording failed; a failure stops it (:meth:`_fail`)."""
        if self.error is None:
            try:
                log(*args)
            except (RuntimeError, OSError) as exc:
                self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        """Stop recording on a writer failure (rerun's file sink reports a full disk as a
        ``RuntimeError``), keeping what was written; never raises."""
        if self.error is None:
            self.error = f"{self.path}: {exc}"

    def flush(self) -> None:
        """Send the buffered rows as one column per channel (never raises: a failure stops the
        recording, :attr:`error`)."""
        n = self._n
        self._sent_at = time.monotonic()
        if n == 0:
            return
        self._n = 0
        if self.error is not None:
            return
        try:
            self._send_rows(n)
        except (RuntimeError, OSError) as exc:
            self._fail(exc)

    def _send_rows(self, n: int) -> None:
        indexes = [
            rr.TimeColumn("tick", sequence=self._ticks[:n].copy()),
            rr.TimeColumn("sim_time", duration=self._times[:n].copy()),
        ]
        for j, (entity, _) in enumerate(CHANNELS):
            self._rec.send_columns(
                entity,
                indexes=indexes,
                columns=rr.Scalars.columns(scalars=self._values[:n, j].copy()),
            )
        self.rows_written += n

    def log_series(
        self,
        entity: str,
        label: str,
        ticks: np.ndarray,
        times_s: np.ndarray,
        values: np.ndarray,
    ) -> None:
        """Add a whole series named ``label`` that did not come through the loop (the simulated
        device's true MAP) on the same two timelines; call before :meth:`close`."""
        self._guarded(self._log_series, entity, label, ticks, times_s, values)

    def _log_series(self, entity: str, label: str, ticks: Any, times_s: Any, values: Any) -> None:
        style = rr.SeriesLines(names=label, colors=SERIES_COLORS.get(entity))
        self._rec.log(entity, style, static=True)
        self._rec.send_columns(
            entity,
            indexes=[
                rr.TimeColumn("tick", sequence=np.asarray(ticks, dtype=np.int64)),
                rr.TimeColumn("sim_time", duration=np.asarray(times_s, dtype=np.float64)),
            ],
            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
        )

    def close(self) -> Path | None:
        """Flush, finish the file and move it to ``path``; return ``path`` (``None``: no file). A recording that
        failed (:attr:`error`) is moved into place too, holding what was written before."""
        if self._closed:
            return self.path
        self._closed = True
        self._stop.set()
        self._watch.join()
        self.flush()
        if self._last_tick is not None and self._last_tick != self._first_tick:
            self._guarded(self._log_box, *self._last_tick)
        try:
            self._rec.flush()
        except (RuntimeError, OSError) as exc:
            self._fail(exc)
        self._rec.disconnect()
        if self._target is not None:
            self._target.commit()
        return self.path

    def abort(self) -> None:
        """End the recording of a run that failed: kept, like a finished one (:meth:`close`), since
        the record of a run that went wrong is the one an investigator needs most."""
        self.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
