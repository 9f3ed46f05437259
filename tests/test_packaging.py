"""The wheel installs one import namespace, ``pressor``, and runs from it (setup.py maps the folders).

Built from the checkout as ``pip wheel`` builds it, installed into a fresh virtual environment with
no access to the checkout (the dependencies are lent from this interpreter's site-packages by a
``.pth`` line, so nothing is downloaded but the build backend), then ``pressor sil`` runs there.
"""

from __future__ import annotations

import os
import site
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: files a user's run reads at run time, by their installed path
RUN_TIME_DATA = (
    "pressor/synthesis/data/default_design.npz",
    "pressor/synthesis/data/default_design.toml",
    "pressor/runtime/generated/lpv_map_controller.py",
    "pressor/runtime/generated/lpv_map_controller.c",
    "pressor/runtime/inputs/drug_library.toml",
    "pressor/hil_sim/scenarios/paper-tracking.toml",
    "pressor/hil_sim/native/paper_patient.c",
    "pressor/plumbing/native_call.c",
    "pressor/link/pressor.xml",
)


def run(*cmd: str | Path, cwd: Path, env: dict[str, str] | None = None, timeout: float = 300):
    proc = subprocess.run(
        [str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )
    assert proc.returncode == 0, f"{cmd} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    run(sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", out, ROOT, cwd=out)
    (path,) = out.glob("pressor-*.whl")
    return path


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory, wheel: Path) -> Iterator[tuple[Path, set[str]]]:
    """A fresh venv with the wheel installed; yields its bin directory and what the install added
    to its site-packages."""
    home = tmp_path_factory.mktemp("venv")
    run(sys.executable, "-m", "venv", "--without-pip", home, cwd=home)
    python = home / "bin" / "python"
    purelib = Path(
        run(
            python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))", cwd=home
        ).stdout.strip()
    )
    before = {p.name for p in purelib.iterdir()}
    run(
        sys.executable,
        "-m",
        "pip",
        "--python",
        python,
        "install",
        "-q",
        "--no-deps",
        wheel,
        cwd=home,
    )
    added = {p.name for p in purelib.iterdir()} - before
    # the dependencies, lent by path only: this interpreter's .pth files (the checkout's editable
    # finder among them) are not processed for a directory named in a .pth line
    lent = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (purelib / "zz_lent_dependencies.pth").write_text("\n".join(lent) + "\n")
    yield home / "bin", added


def clean_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["CI"] = "1"
    return env


def test_the_wheel_holds_one_top_level_package_and_the_run_time_data(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
    top = {n.split("/")[0] for n in names if ".dist-info/" not in n}
    assert top == {"pressor"}
    missing = [path for path in RUN_TIME_DATA if path not in names]
    assert missing == []
    assert not any("__pycache__" in n or n.startswith(("tests/", "research/")) for n in names)


def test_installing_the_wheel_adds_only_pressor_to_site_packages(venv) -> None:
    _, added = venv
    assert {name for name in added if not name.endswith(".dist-info")} == {"pressor"}


def test_the_installed_package_imports_from_the_venv_and_no_folder_name_leaks(
    venv, tmp_path: Path
) -> None:
    bin_dir, _ = venv
    code = (
        "import importlib.util, pressor.runtime.session, pressor.hil_sim.world;"
        "print(pressor.runtime.session.__file__);"
        "print([n for n in ('runtime', 'hil_sim', 'sim', 'link', 'synthesis', 'codegen',"
        " 'contracts', 'plumbing', 'baselines') if importlib.util.find_spec(n)])"
    )
    out = run(bin_dir / "python", "-c", code, cwd=tmp_path, env=clean_env()).stdout.splitlines()
    assert out[0].startswith(str(bin_dir.parent)) and out[0].endswith("pressor/runtime/session.py")
    assert out[1] == "[]"


def test_pressor_sil_runs_from_the_installed_wheel(venv, tmp_path: Path) -> None:
    bin_dir, _ = venv
    rrd = tmp_path / "sil.rrd"
    proc = run(
        bin_dir / "pressor", "sil", "--duration", "60", "--rrd", rrd, cwd=tmp_path, env=clean_env()
    )
    assert rrd.stat().st_size > 0
    assert "overshoot" in proc.stdout
