"""The live view's viewer (``--view``): rerun's native viewer where there is a display, else its
web viewer served on 127.0.0.1.

:func:`start_viewer` starts ``rerun`` as a process of its own (its own session, so a Ctrl-C meant
for the run does not reach it) listening for the recording on a gRPC port, or reuses the viewer
already listening there (an earlier run's: the new run opens beside it). The native viewer opens a
window; the web one serves the page to open (:attr:`Viewer.open_url`, printed on one line) and
buffers what it was sent for a browser that connects late. Either outlives the run, so a lockstep
run, over in seconds, can be looked at afterwards: the native one until its window is closed,
the web one until its process is ended (its pid is printed). The run never waits for it: closing
it, or a viewer that does not start, leaves the run and its ``.rrd`` as they were
(:mod:`pressor.runtime.record.live`).
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

NATIVE, WEB = "native", "web"
#: the viewer's gRPC port unless ``--view-port``: rerun's own default, where a native viewer
#: started by hand (``rerun``) listens; the web viewer's page is served on the next port
DEFAULT_VIEW_PORT = 9876
#: ``--view-port``'s range: unprivileged ports, and room for the web page's port after it
VIEW_PORT_MIN, VIEW_PORT_MAX = 1024, 65534
#: wall seconds a new viewer has to start listening before the run goes on without it
START_TIMEOUT_S = 15.0


class ViewerError(RuntimeError):
    """The viewer could not be started (no ``rerun`` executable, it exited, it never listened)."""


def has_display(environ: Mapping[str, str] | None = None) -> bool:
    """Whether a native window can open here: ``DISPLAY`` or ``WAYLAND_DISPLAY`` set."""
    env = os.environ if environ is None else environ
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def viewer_kind(environ: Mapping[str, str] | None = None) -> str:
    """:data:`NATIVE` where there is a display (:func:`has_display`), else :data:`WEB`."""
    return NATIVE if has_display(environ) else WEB


def grpc_url(port: int) -> str:
    """The URL a recording stream connects to, for a viewer listening on ``port``."""
    return f"rerun+http://127.0.0.1:{port}/proxy"


def web_url(port: int) -> str:
    """The page to open for the web viewer whose gRPC port is ``port`` (page on ``port + 1``)."""
    return f"http://127.0.0.1:{port + 1}/?url={quote(grpc_url(port), safe='')}"


def rerun_executable() -> str:
    """The ``rerun`` viewer binary of the installed ``rerun-sdk`` (``RERUN_CLI_PATH`` overrides
    it, as for rerun's own launcher), else ``rerun`` on ``PATH``."""
    if os.environ.get("RERUN_CLI_PATH"):
        return os.environ["RERUN_CLI_PATH"]
    try:
        import rerun_cli

        binary = Path(rerun_cli.__file__).parent / "rerun"
        if binary.is_file():
            return str(binary)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise ViewerError("no rerun executable (it ships with rerun-sdk)")
    return found


def viewer_command(kind: str, port: int, executable: str = "rerun") -> list[str]:
    """The command line of a viewer of ``kind`` listening for recordings on 127.0.0.1:``port``
    (the web viewer's page on ``port + 1``, on 127.0.0.1 too)."""
    common = ["--bind", "127.0.0.1", "--port", str(port)]
    if kind == WEB:
        return [executable, "--serve-web", *common, "--web-viewer-port", str(port + 1)]
    if kind == NATIVE:
        return [executable, *common, "--expect-data-soon", "--hide-welcome-screen"]
    raise ValueError(f"viewer kind {kind!r}: allowed {NATIVE}, {WEB}")


@dataclass(frozen=True)
class Viewer:
    """A viewer the run streams to.

    Attributes
    ----------
    kind
        :data:`NATIVE` or :data:`WEB`.
    port
        Its gRPC port on 127.0.0.1.
    pid
        The process started for it; ``None`` when one was listening already (reused).
    """

    kind: str
    port: int
    pid: int | None

    @property
    def url(self) -> str:
        """Where the recording stream connects (:func:`grpc_url`)."""
        return grpc_url(self.port)

    @property
    def open_url(self) -> str | None:
        """The web viewer's page to open in a browser; ``None`` for the native viewer."""
        return web_url(self.port) if self.kind == WEB else None

    def announce(self) -> str:
        """One line for the user: where to look, and how to stop a web viewer started here."""
        who = "the viewer already there" if self.pid is None else f"pid {self.pid}"
        if self.kind == WEB:
            after = "" if self.pid is None else f"; it stays after the run: kill {self.pid} ends it"
            return f"live view: open {self.open_url}  (rerun web viewer, {who}{after})"
        return f"live view: rerun viewer on port {self.port} ({who})"


def listening(port: int) -> bool:
    """Whether something accepts TCP connections on 127.0.0.1:``port``."""
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def start_viewer(
    kind: str, port: int = DEFAULT_VIEW_PORT, timeout_s: float = START_TIMEOUT_S
) -> Viewer:
    """Start a viewer of ``kind`` on ``port`` (or reuse the one listening there) and return once
    it accepts connections.

    Raises
    ------
    ViewerError
        No ``rerun`` executable, or it exited or did not listen within ``timeout_s`` wall seconds
        (its last line of output says why, e.g. a port in use).
    """
    if listening(port):
        return Viewer(kind, port, None)
    command = viewer_command(kind, port, rerun_executable())
    # its output goes to a file already unlinked: read if it fails to start, and a viewer that
    # outlives the run never writes into a closed pipe
    with tempfile.TemporaryFile() as log:
        try:
            proc = subprocess.Popen(
                command,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                env={**os.environ, "RERUN_APP_ONLY": "true"},  # as rerun's own spawn: no prompts
            )
        except OSError as exc:
            raise ViewerError(f"{command[0]}: {exc.strerror or exc}") from None
        deadline = time.monotonic() + timeout_s
        while not (listening(port) and (kind != WEB or listening(port + 1))):
            if proc.poll() is not None or time.monotonic() > deadline:
                code = proc.poll()
                if code is None:
                    proc.terminate()
                    proc.wait()
                log.seek(0)
                lines = log.read().decode(errors="replace").strip().splitlines()
                why = lines[-1] if lines else f"exit code {proc.returncode}"
                state = (
                    f"exited ({code})" if code is not None else f"not listening in {timeout_s:g} s"
                )
                raise ViewerError(f"rerun viewer on port {port} {state}: {why}")
            time.sleep(0.05)
        if kind == WEB and not _serves_rerun_page(port + 1):
            # the page's port answered, but not with rerun's page: another program holds it
            # (rerun exits, but perhaps only after its gRPC port came up)
            proc.terminate()
            proc.wait()
            raise ViewerError(f"port {port + 1} (the web page's) is taken by another program")
    return Viewer(kind, port, proc.pid)


def _serves_rerun_page(port: int, timeout_s: float = 5.0) -> bool:
    """Whether http://127.0.0.1:``port``/ answers with rerun's web viewer page."""
    import urllib.request

    direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # never via http_proxy
    try:
        with direct.open(f"http://127.0.0.1:{port}/", timeout=timeout_s) as reply:
            return b"rerun" in reply.read(4096).lower()
    except OSError:
        return False


def open_view(port: int, prog: str, environ: Mapping[str, str] | None = None) -> str | None:
    """Start (or reuse) the viewer :func:`viewer_kind` picks for this machine on ``port``, say on
    stderr where to look (one line) and return the URL to stream to; a viewer that does not
    start is said too (one line) and the run goes on without it (``None``)."""
    import sys

    try:
        viewer = start_viewer(viewer_kind(environ), port)
    except ViewerError as exc:
        print(f"{prog}: --view: no viewer, the run goes on without it: {exc}", file=sys.stderr)
        return None
    print(f"{prog}: {viewer.announce()}", file=sys.stderr, flush=True)
    return viewer.url
