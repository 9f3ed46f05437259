"""Fixtures more than one test module uses. Doubles, devices and helpers are in tests/support/."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from tests.support.protocol_device import build_dialect
from tests.support.sil_helpers import bridged_ttys

ROOT = Path(__file__).resolve().parents[1]


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
