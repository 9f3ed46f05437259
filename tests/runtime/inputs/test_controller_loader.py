"""The loader refuses research builds of uncertified laws (runtime/inputs/controller_loader.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from pressor.contracts.module_hash import module_text_sha256
from pressor.runtime.inputs.controller_loader import (
    UNCERTIFIED_MARK,
    ControllerSpecError,
    load_controller,
    lpv_design_module,
)


def _research_build(tmp_path: Path) -> Path:
    # the shipped module's text with an uncertified build's generation command, its self-hash
    # recomputed as the research build writes it
    shipped = lpv_design_module("lpv")
    assert shipped is not None
    text = shipped.read_text(encoding="utf-8")
    text = re.sub(
        r"^GENERATION_COMMAND = '[^']*'",
        f"GENERATION_COMMAND = '{UNCERTIFIED_MARK}research/designs/wide_delay.toml'",
        text,
        count=1,
        flags=re.MULTILINE,
    )
    text = re.sub(r"^MODULE_SHA256 = '[0-9a-f]{64}'", f"MODULE_SHA256 = '{'0' * 64}'", text,
                  count=1, flags=re.MULTILINE)  # fmt: skip
    text = text.replace("0" * 64, module_text_sha256(text), 1)
    path = tmp_path / "research.py"
    path.write_text(text, encoding="utf-8")
    return path


def test_an_uncertified_research_build_is_refused_by_default(tmp_path):
    path = _research_build(tmp_path)
    with pytest.raises(ControllerSpecError, match="UNCERTIFIED research build"):
        load_controller(str(path))


def test_an_uncertified_research_build_runs_when_the_caller_allows_it(tmp_path):
    controller = load_controller(str(_research_build(tmp_path)), allow_uncertified=True)
    assert 0.0 <= controller.step(60.0, 70.0, 0.55, 150.0, 40.0) <= 120.0
