"""Take a screenshot of a recording, or of a live run, in the real rerun web viewer, in headless
Chromium.

This is how ``docs/img/viewer.png`` (the README's viewer picture) is made, by
``scripts/docs_images.sh``::

    pressor sil --rrd sil.rrd
    python scripts/viewer_screenshot.py sil.rrd docs/img/viewer.png --wait-s 200

It starts ``rerun --serve-web`` on two free localhost ports (the web viewer over HTTP and the
gRPC proxy that streams the recording), opens the viewer in headless Chromium driven by
Playwright, waits for the recording to load and render, saves the PNG and stops both.

A live run (``pressor sil --view`` without a display prints the page to open) is photographed
by giving that URL instead of a recording; the viewer is the run's, left running::

    pressor sil --view --realtime &
    python scripts/viewer_screenshot.py 'http://127.0.0.1:9877/?url=...' live.png --wait-s 120

Needs (not part of the test install): Chromium (Debian: ``apt-get install chromium``, which puts
it at ``/usr/bin/chromium``) and Playwright's Python package (``pip install -e ".[screenshot]"``;
no Playwright browser download: the system Chromium is used). Without a GPU Chromium renders
WebGL with SwiftShader, so loading and drawing an hour-long recording takes about a minute on two
cores: hence the generous default wait.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

#: Chromium flags for a closed network and no GPU (software WebGL through SwiftShader)
CHROMIUM_ARGS = (
    "--no-sandbox",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--ignore-gpu-blocklist",
)


def free_port() -> int:
    """A TCP port on localhost that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_port(port: int, timeout_s: float) -> None:
    """Return once something accepts connections on ``port``; raise after ``timeout_s`` (s)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError(f"nothing listens on port {port} after {timeout_s} s")


def photograph(
    url: str, out: Path, *, chromium: str, width: int, height: int, wait_s: float
) -> None:
    """Open ``url`` (a rerun web viewer's page) in headless Chromium, wait ``wait_s`` (s) for it
    to load and draw, and save what it shows as the PNG ``out``."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=chromium, headless=True, args=list(CHROMIUM_ARGS)
        )
        page = browser.new_page(viewport={"width": width, "height": height})
        page.goto(url)
        page.wait_for_timeout(wait_s * 1000.0)
        out.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(out))
        browser.close()


def screenshot(
    rrd: Path,
    out: Path,
    *,
    chromium: str,
    width: int,
    height: int,
    wait_s: float,
) -> None:
    """Serve ``rrd`` with rerun's web viewer and save what a browser shows as the PNG ``out``."""
    from pressor.runtime.shell.viewer import rerun_executable

    http_port, grpc_port = free_port(), free_port()
    server = subprocess.Popen(
        [
            rerun_executable(),  # the installed rerun-sdk's viewer, on PATH or not
            "--serve-web",
            "--bind",
            "127.0.0.1",
            "--web-viewer-port",
            str(http_port),
            "--port",
            str(grpc_port),
            str(rrd),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # a `rerun` launcher on PATH runs the viewer as its child
    )
    try:
        wait_for_port(http_port, 30.0)
        wait_for_port(grpc_port, 30.0)
        url = (
            f"http://127.0.0.1:{http_port}/"
            f"?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy"
        )
        photograph(url, out, chromium=chromium, width=width, height=height, wait_s=wait_s)
    finally:
        os.killpg(server.pid, signal.SIGTERM)  # the launcher and its server
        server.wait(timeout=10)


def main(argv: list[str] | None = None) -> int:
    """Command line: ``viewer_screenshot.py RRD|URL OUT.png [--wait-s S] ...``."""
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument(
        "source",
        help="the recording to show (.rrd), or the http://127.0.0.1 URL of a running web viewer"
        " (a live run: the page pressor sil --view prints)",
    )
    p.add_argument("out", type=Path, help="the PNG to write")
    p.add_argument("--chromium", default="/usr/bin/chromium", help="Chromium executable")
    p.add_argument("--width", type=int, default=1600, help="viewport width (px)")
    p.add_argument("--height", type=int, default=1000, help="viewport height (px)")
    p.add_argument(
        "--wait-s",
        type=float,
        default=90.0,
        help="time to let the viewer load and draw before the screenshot (s)",
    )
    a = p.parse_args(argv)
    live = a.source.startswith(("http://127.0.0.1:", "http://localhost:"))
    if not live and not Path(a.source).is_file():
        p.error(f"recording {a.source} does not exist (or give a http://127.0.0.1:PORT/ URL)")
    if not Path(a.chromium).is_file():
        p.error(f"no Chromium at {a.chromium} (Debian: apt-get install chromium)")
    if not 0.0 < a.wait_s <= 600.0:
        p.error(f"--wait-s {a.wait_s} s is outside (0, 600] s")
    size = {"chromium": a.chromium, "width": a.width, "height": a.height, "wait_s": a.wait_s}
    if live:
        photograph(a.source, a.out, **size)
    else:
        screenshot(Path(a.source), a.out, **size)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
