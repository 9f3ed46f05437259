"""The recording's live copy: what the recorder logs, streamed to a viewer as the run goes.

The ``.rrd`` file and the viewer get two rerun streams with the same recording id rather than one
stream with two sinks: a stream reports a sink's failure to every flush, so a viewer closed
mid-run (its gRPC connection severed) would read as the file's failure and stop the recording. So
:class:`Tee` hands every call to the file's stream first (its errors reach the recorder as
before, the file's bytes are the same as without a viewer) and then to :class:`LiveStream`,
which never raises: once its viewer is gone it stops sending, and the run goes on.

Nothing of the viewer's stream waits on the caller's thread (the loop's): connecting to a viewer
that does not answer takes rerun 5 s, and so does disconnecting while it still tries, so both run
on threads of their own (what is logged before the connection is up waits in the stream's buffer
and is sent once it is). Its flush at the end of the run is bounded (:data:`CLOSE_FLUSH_S`): a
stream whose viewer never answers would otherwise wait for good.
"""

from __future__ import annotations

import socket
import threading
import uuid
from typing import Any
from urllib.parse import urlsplit

import rerun as rr

#: wall seconds the live stream's last flush may take at the end of the run
CLOSE_FLUSH_S = 5.0
#: how long a health check (a flush) may wait for a slow viewer before it is asked again later
_CHECK_S = 0.05


def new_stream(recording_id: uuid.UUID) -> rr.RecordingStream:
    """A reproducible rerun stream: no wall-clock timelines, no properties (which carry the start
    time), the given recording id."""
    rec = rr.RecordingStream("pressor", recording_id=recording_id, send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    return rec


class LiveStream:
    """The stream to a viewer at ``url`` (``rerun+http://HOST:PORT/proxy``), opened with
    ``blueprint``; every method swallows rerun's errors.

    Attributes
    ----------
    lost
        Why the viewer stopped receiving (its connection severed: closed by the user), else
        ``None``. Once set, nothing more is sent.
    """

    def __init__(self, url: str, recording_id: uuid.UUID, blueprint: Any) -> None:
        self.lost: str | None = None
        self._rec: rr.RecordingStream | None = new_stream(recording_id)
        self._connecting = threading.Thread(
            target=self._connect, args=(self._rec, url, blueprint), name="live view", daemon=True
        )
        self._connecting.start()

    def _connect(self, rec: rr.RecordingStream, url: str, blueprint: Any) -> None:
        where = urlsplit(url)
        try:
            # rerun waits 5 s on a port nobody listens on (a viewer closed since it was started),
            # then 5 s more to give up at the end of the run: a plain TCP probe says it at once
            socket.create_connection((where.hostname, where.port), timeout=1.0).close()
            rec.connect_grpc(url, default_blueprint=blueprint)
        except (RuntimeError, OSError, ValueError) as exc:
            self._drop(exc)

    def call(self, name: str, *args: Any, **kwargs: Any) -> None:
        """``stream.<name>(*args, **kwargs)`` unless the viewer is gone."""
        rec = self._rec  # read once: the sink watcher's thread may drop it meanwhile
        if rec is None:
            return
        try:
            getattr(rec, name)(*args, **kwargs)
        except (RuntimeError, OSError, ValueError) as exc:
            self._drop(exc)

    def check(self) -> None:
        """Notice a viewer that went away (a short flush reports a severed connection) and stop
        sending to it; a flush that only ran out of time is not a loss."""
        self._flush(_CHECK_S)

    def close(self) -> None:
        """Send what is left and disconnect: at most about 2 × :data:`CLOSE_FLUSH_S` s, for a
        viewer still connecting when the run ends; a viewer that went away costs nothing."""
        self._connecting.join(CLOSE_FLUSH_S)
        if self._connecting.is_alive():  # nothing answers: give up on it without waiting more
            self._drop(TimeoutError(f"no viewer answered in {CLOSE_FLUSH_S:g} s"))
            return
        self._flush(CLOSE_FLUSH_S)
        rec, self._rec = self._rec, None
        if rec is not None:
            _disconnect(rec)

    def _flush(self, timeout_s: float) -> None:
        rec = self._rec
        if rec is None:
            return
        try:
            rec.flush(timeout_sec=timeout_s)
        except RuntimeError as exc:
            if "timed out" not in str(exc):
                self._drop(exc)

    def _drop(self, exc: BaseException) -> None:
        """Stop sending; disconnect on a thread of its own (it may wait for a reconnection)."""
        self.lost = str(exc)
        rec, self._rec = self._rec, None
        if rec is not None:
            threading.Thread(
                target=_disconnect, args=(rec,), name="live view end", daemon=True
            ).start()


def _disconnect(rec: rr.RecordingStream) -> None:
    try:
        rec.disconnect()
    except (RuntimeError, OSError):
        pass


class Tee:
    """The recorder's stream: the file's (``primary``, ``None`` for a run recorded to a viewer
    only) and the viewer's (``live``). Logging goes to both; flushing waits for the file only
    (and checks on the viewer); disconnecting ends both."""

    def __init__(self, primary: rr.RecordingStream | None, live: LiveStream) -> None:
        self.primary = primary
        self.live = live

    def _both(self, name: str, *args: Any, **kwargs: Any) -> None:
        if self.primary is not None:
            getattr(self.primary, name)(*args, **kwargs)
        self.live.call(name, *args, **kwargs)

    def log(self, *args: Any, **kwargs: Any) -> None:
        self._both("log", *args, **kwargs)

    def send_columns(self, *args: Any, **kwargs: Any) -> None:
        self._both("send_columns", *args, **kwargs)

    def set_time(self, *args: Any, **kwargs: Any) -> None:
        self._both("set_time", *args, **kwargs)

    def send_recording_name(self, *args: Any, **kwargs: Any) -> None:
        self._both("send_recording_name", *args, **kwargs)

    def flush(self, timeout_sec: float | None = None) -> None:
        """Flush the file's stream (its errors raised, as rerun's); check on the viewer."""
        self.live.check()
        if self.primary is not None:
            if timeout_sec is None:
                self.primary.flush()
            else:
                self.primary.flush(timeout_sec=timeout_sec)

    def disconnect(self) -> None:
        """End the viewer's stream (a bounded last flush), then the file's."""
        self.live.close()
        if self.primary is not None:
            self.primary.disconnect()
