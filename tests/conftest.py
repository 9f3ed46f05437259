"""Fixtures more than one test module uses. Doubles, devices and helpers are in tests/support/."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from pressor.plumbing.native_build import CACHE_ENV
from tests.support.protocol_device import build_dialect
from tests.support.sil_helpers import bridged_ttys

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session", autouse=True)
def native_cache() -> Iterator[Path]:
    """Compiled twins (pressor.plumbing.native_build) go to a directory of this test session, not the
    user's cache; subprocesses the tests start inherit it."""
    path = Path(tempfile.mkdtemp(prefix="pressor-native-"))
    old = os.environ.get(CACHE_ENV)
    os.environ[CACHE_ENV] = str(path)
    yield path
    if old is None:
        os.environ.pop(CACHE_ENV, None)
    else:
        os.environ[CACHE_ENV] = old
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def bridged_ports() -> Iterator[tuple[str, str]]:
    """Two tty paths whose bytes cross over, like a null-modem cable."""
    with bridged_ttys() as ports:
        yield ports


@pytest.fixture(scope="session")
def dialect(tmp_path_factory: pytest.TempPathFactory) -> ModuleType:
    """The protocol device's own bindings, generated from link/pressor.xml with pymavlink's
    mavgen (tests/support/protocol_device.py)."""
    return build_dialect(ROOT / "link" / "pressor.xml", tmp_path_factory.mktemp("dialect"))


#: a 5-minute paper-disturbance (a +20 mmHg step, a haemorrhage at 2 min) for quick cohorts
SHORT_SCENARIO_TOML = """
name = "short-disturbance"
description = "5 min version of paper-disturbance for tests"
duration_s = 300.0
[patient]
mode = "nonlinear"
[target]
step_mmhg = 20.0
[sensor]
noise_std_mmhg = 0.1
[[disturbances]]
kind = "hemorrhage"
start_s = 120.0
ramp_s = 60.0
depth_mmhg = 10.0
"""


@pytest.fixture
def short_scenario(tmp_path: Path) -> Path:
    """The path of :data:`SHORT_SCENARIO_TOML` written to a scenario file."""
    path = tmp_path / "short.toml"
    path.write_text(SHORT_SCENARIO_TOML)
    return path


#: a 4-minute paper-tracking (a +20 mmHg step, no disturbance) for trial plumbing tests
SHORT_TRACKING_TOML = """
name = "short-tracking"
description = "4 min paper-tracking for tests"
duration_s = 240.0
[patient]
mode = "nonlinear"
[target]
step_mmhg = 20.0
[sensor]
noise_std_mmhg = 0.1
"""


@pytest.fixture
def short_tracking_scenario(tmp_path: Path) -> Path:
    """The path of :data:`SHORT_TRACKING_TOML` written to a scenario file."""
    path = tmp_path / "short-tracking.toml"
    path.write_text(SHORT_TRACKING_TOML)
    return path
