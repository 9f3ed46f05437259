"""``--view``: the run streamed to a real rerun viewer while it runs (issue 40, "a live view").

The viewer is the real ``rerun`` binary serving its web viewer on 127.0.0.1; the client that
checks what it serves is the real ``rerun`` binary too (``rerun --save FILE URL`` connects to the
viewer's gRPC proxy like a browser tab does and writes what it receives). Every viewer a test
starts is ended by its pid.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from pressor.runtime.record.channels import CHANNELS
from pressor.runtime.record.recorder import Recorder
from pressor.runtime.shell.viewer import (
    NATIVE,
    WEB,
    grpc_url,
    rerun_executable,
    start_viewer,
    viewer_command,
    viewer_kind,
    web_url,
)
from tests.support.sil_helpers import rrd_columns

#: the line ``--view`` prints for a web viewer it started: the page's port and the pid
ANNOUNCE = re.compile(r"live view: open http://127\.0\.0\.1:(\d+)/\?url=\S+ .*kill (\d+) ends it")


def free_port_pair() -> int:
    """A port P with P and P + 1 free on 127.0.0.1 (the viewer's gRPC port and its page's)."""
    for _ in range(100):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port >= 65535:
            continue
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port + 1)) != 0:
                return port
    raise RuntimeError("no two adjacent free ports")


def no_display() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return {**env, "CI": "1"}


def end(pid: int) -> None:
    """End a viewer process this test started, by its pid."""
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        pass


def client_capture(port: int, out: Path, expect_entity: str, timeout_s: float = 20.0) -> Path:
    """Connect a real rerun client to the viewer on ``port`` (``rerun --save``) until what it
    wrote holds ``expect_entity``'s whole series twice in a row (it stopped growing); return
    the file it wrote."""
    own = free_port_pair()  # the client's own gRPC server, off rerun's default port
    cmd = [rerun_executable(), "--save", str(out), "--bind", "127.0.0.1", "--port", str(own)]
    client = subprocess.Popen(
        [*cmd, grpc_url(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "RERUN_APP_ONLY": "true"},
    )
    try:
        deadline, last = time.monotonic() + timeout_s, -1
        while time.monotonic() < deadline:
            time.sleep(0.5)
            if not out.is_file():
                continue
            with warnings.catch_warnings():  # a file still being written has no footer
                warnings.simplefilter("ignore")
                try:
                    n = len(rrd_columns(out).get(expect_entity, {}))
                except (ValueError, OSError):
                    continue
            if n > 0 and n == last:
                break
            last = n
    finally:
        client.terminate()
        client.wait(timeout=10)
    return out


def sil_view(
    cwd: Path, port: int, duration_s: int, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess:
    """A finished ``pressor sil --view`` run of ``duration_s`` s recording ``run.rrd`` in ``cwd``
    (default environment: no display)."""
    return subprocess.run(
        [sys.executable, "-m", "pressor", "sil", "--view", "--view-port", str(port)]
        + ["--duration", str(duration_s), "--rrd", "run.rrd", "--no-signing"],
        cwd=cwd,
        env=no_display() if env is None else env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def same(a: dict[int, float], b: dict[int, float]) -> bool:
    """Equal series, NaN (no value at that tick) equal to NaN."""
    return a.keys() == b.keys() and all(a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]) for k in a)


def test_native_viewer_where_there_is_a_display_else_the_web_viewer():
    assert viewer_kind({}) == WEB
    assert viewer_kind({"DISPLAY": ""}) == WEB
    assert viewer_kind({"DISPLAY": ":0"}) == NATIVE
    assert viewer_kind({"WAYLAND_DISPLAY": "wayland-0"}) == NATIVE


def test_viewer_listens_on_localhost_only_with_options_the_installed_rerun_has():
    web = viewer_command(WEB, 9876, "rerun")
    assert web[:2] == ["rerun", "--serve-web"]
    assert web[web.index("--bind") + 1] == "127.0.0.1"
    assert web[web.index("--port") + 1] == "9876"
    assert web[web.index("--web-viewer-port") + 1] == "9877"
    native = viewer_command(NATIVE, 9876, "rerun")
    assert "--serve-web" not in native and native[native.index("--bind") + 1] == "127.0.0.1"
    help_text = subprocess.run(
        [rerun_executable(), "--help"], capture_output=True, text=True, timeout=30
    ).stdout
    for option in {o for o in web + native if o.startswith("--")}:
        assert f"  {option}" in help_text, option
    assert web_url(9876) == (
        "http://127.0.0.1:9877/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9876%2Fproxy"
    )


@pytest.fixture(scope="module")
def viewed_sil(tmp_path_factory) -> Iterator[tuple[Path, int, int, subprocess.CompletedProcess]]:
    """A ``pressor sil --view`` run without a display: (its folder, the viewer's gRPC port, its
    pid, the finished process); the viewer is ended after the module's tests."""
    d = tmp_path_factory.mktemp("view")
    port = free_port_pair()
    proc = sil_view(d, port, 20)
    match = ANNOUNCE.search(proc.stderr)
    assert match is not None, proc.stderr
    pid = int(match.group(2))
    try:
        assert int(match.group(1)) == port + 1
        yield d, port, pid, proc
    finally:
        end(pid)


def test_sil_view_serves_the_web_viewer_page_on_localhost(viewed_sil):
    _, port, _, proc = viewed_sil
    assert proc.returncode == 0, proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if "live view" in ln]  # one line
    page = urllib.request.urlopen(f"http://127.0.0.1:{port + 1}/", timeout=10).read()
    assert b"<html" in page.lower() and b"rerun" in page.lower()


def test_a_viewer_client_receives_the_whole_run_and_its_layout_as_the_rrd_holds_them(viewed_sil):
    from rerun.chunk import RrdReader

    d, port, _, _ = viewed_sil
    recorded = rrd_columns(d / "run.rrd")
    assert {entity for entity, _ in CHANNELS} <= set(recorded)
    assert "/patient/map_true_mmhg" in recorded  # added when the run ended: sent live too
    assert sorted(recorded["/patient/map_mmhg"]) == list(range(200))
    got = client_capture(port, d / "client.rrd", "/patient/map_true_mmhg")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        received = rrd_columns(got)
        blueprints = RrdReader(str(got)).blueprints()
    for entity in ("/patient/map_mmhg", "/pump/rate_ml_h", "/patient/map_true_mmhg"):
        assert same(received[entity], recorded[entity]), entity
    assert [b.application_id for b in blueprints] == ["pressor"]  # the recording's layout


def test_a_viewer_closed_mid_recording_stops_its_copy_only(tmp_path):
    port = free_port_pair()
    viewer = start_viewer(WEB, port)
    assert viewer.pid is not None
    try:
        rec = Recorder(tmp_path / "r.rrd", run_label="closed", chunk_ticks=16, live=viewer.url)
        for k in range(100):
            rec.record(k, k * 0.1, [float(k)] * len(CHANNELS))
            if k == 40:
                end(viewer.pid)  # the user closes the viewer
                time.sleep(2.0)  # the sink watcher looks once a second
        started = time.monotonic()
        rec.close()
        took = time.monotonic() - started
    finally:
        end(viewer.pid)
    # one stream with a file sink and a gRPC sink reported the severed connection to the file's
    # flush: the recording stopped there (error set, ticks 41-99 lost)
    assert rec.error is None
    assert rec.viewer_lost is not None and "gRPC" in rec.viewer_lost
    assert sorted(rrd_columns(tmp_path / "r.rrd")["/patient/map_mmhg"]) == list(range(100))
    assert took < 2.0  # nothing waits for the viewer that went away


def test_a_viewer_gone_before_the_recording_connects_costs_nothing(tmp_path):
    port = free_port_pair()  # nobody listens: the viewer was closed since it was started
    started = time.monotonic()
    rec = Recorder(tmp_path / "r.rrd", run_label="gone", chunk_ticks=16, live=grpc_url(port))
    for k in range(50):
        rec.record(k, k * 0.1, [float(k)] * len(CHANNELS))
    rec.close()
    # rerun alone waits 5 s to connect to nobody, and 5 s more to give up when disconnected
    assert time.monotonic() - started < 3.0
    assert rec.error is None and rec.viewer_lost is not None
    assert sorted(rrd_columns(tmp_path / "r.rrd")["/patient/map_mmhg"]) == list(range(50))


@pytest.mark.slow
def test_closing_the_viewer_mid_run_leaves_the_realtime_run_and_its_recording_whole(tmp_path):
    port = free_port_pair()
    proc = subprocess.Popen(
        [sys.executable, "-m", "pressor", "sil", "--view", "--view-port", str(port)]
        + ["--realtime", "--duration", "5", "--rrd", "run.rrd", "--summary", "s.json"]
        + ["--no-signing"],
        cwd=tmp_path,
        env=no_display(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()  # the announcement comes first, before the run starts
    match = ANNOUNCE.search(line)
    assert match is not None, line
    pid = int(match.group(2))
    try:
        time.sleep(2.0)  # the run is under way (the device's start, then 5 s of real time)
        end(pid)  # the user closes the viewer
        _, err = proc.communicate(timeout=60)
    finally:
        end(pid)
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    import json

    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["ended"] == "completed"
    assert sorted(rrd_columns(tmp_path / "run.rrd")["/patient/map_mmhg"]) == list(range(50))


def test_a_viewer_that_cannot_start_is_said_in_one_line_and_the_run_goes_on(tmp_path):
    port = free_port_pair()
    with socket.socket() as taken:  # the web page's port is in use: rerun cannot serve it
        taken.bind(("127.0.0.1", port + 1))
        taken.listen()
        proc = sil_view(tmp_path, port, 10)
    assert proc.returncode == 0, proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if "--view" in ln]
    assert line.startswith("pressor sil: --view: no viewer, the run goes on without it: ")
    assert sorted(rrd_columns(tmp_path / "run.rrd")["/patient/map_mmhg"]) == list(range(100))


def test_view_port_outside_its_range_is_refused_naming_it(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "pressor", "sil", "--view", "--view-port", "80"],
        cwd=tmp_path,
        env=no_display(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()[-1:]
    assert "--view-port" in line and "80" in line and "1024" in line and "65534" in line


@pytest.mark.parametrize("command", ["run", "sil"])
def test_help_says_what_view_does(command):
    out = subprocess.run(
        [sys.executable, "-m", "pressor", command, "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "COLUMNS": "200"},
    ).stdout
    text = " ".join(out.split())
    assert "--view " in text and "web viewer served on 127.0.0.1" in text
    assert "native viewer where there is a display" in text


def test_a_recording_to_a_viewer_only_needs_no_file(tmp_path):
    """``pressor run --view`` without ``--rrd``: the recorder streams to the viewer alone."""
    port = free_port_pair()
    viewer = start_viewer(WEB, port)
    assert viewer.pid is not None
    try:
        rec = Recorder(None, run_label="viewer only", chunk_ticks=16, live=viewer.url)
        for k in range(40):
            rec.record(k, k * 0.1, [float(k)] * len(CHANNELS))
        assert rec.close() is None
        assert list(tmp_path.iterdir()) == []
        got = client_capture(port, tmp_path / "client.rrd", "/patient/map_mmhg")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            received = rrd_columns(got)["/patient/map_mmhg"]
        assert received == {k: float(k) for k in range(40)}
    finally:
        end(viewer.pid)


def test_pressor_run_view_without_rrd_streams_the_run_and_its_dose_to_the_viewer(
    bridged_ports, tmp_path
):
    device_port, runtime_port = bridged_ports
    port = free_port_pair()
    env = no_display()
    device = subprocess.Popen(
        [sys.executable, "-m", "pressor", "device", "--port", device_port, "--duration", "10"]
        + ["--no-signing"],
        cwd=tmp_path,
        env=env,
        stderr=subprocess.DEVNULL,
    )
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "pressor", "run", "--port", runtime_port, "--no-signing"]
            + ["--view", "--view-port", str(port), "--controller", "pi"],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        assert device.wait(timeout=30) == 0
    match = ANNOUNCE.search(proc.stderr)
    assert match is not None, proc.stderr
    pid = int(match.group(2))
    try:
        assert proc.returncode == 0, proc.stderr
        assert not list(tmp_path.glob("*.rrd"))  # no --rrd: the viewer holds the only copy
        got = client_capture(port, tmp_path / "client.rrd", "/dose/command_ug_min")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            received = rrd_columns(got)
    finally:
        end(pid)
    assert sorted(received["/patient/map_mmhg"]) == list(range(100))
    assert sorted(received["/dose/command_ug_min"]) == list(range(100))  # added at the end


def test_with_a_display_the_native_viewer_is_started_and_a_dead_one_leaves_the_run_going(
    tmp_path,
):
    """``DISPLAY`` names a display nobody serves: the native viewer is the one started (its
    command line accepted by the real binary), it dies opening its window, and the run goes on."""
    port = free_port_pair()
    proc = sil_view(tmp_path, port, 10, env={**no_display(), "DISPLAY": ":97"})
    assert proc.returncode == 0, proc.stderr
    line = next(ln for ln in proc.stderr.splitlines() if "--view" in ln or "live view" in ln)
    match = re.search(r"live view: rerun viewer on port (\d+) \(pid (\d+)\)", line)
    if match is not None:  # it listened before it died
        end(int(match.group(2)))
        assert int(match.group(1)) == port
    else:  # it died before it listened
        assert line.startswith("pressor sil: --view: no viewer, the run goes on without it"), line
    assert sorted(rrd_columns(tmp_path / "run.rrd")["/patient/map_mmhg"]) == list(range(100))
