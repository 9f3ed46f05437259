"""The committed generated module for the shipped default design is current and works."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

from codegen import pipeline as pl

COMMITTED = Path(pl.REPO_ROOT) / "runtime" / "generated" / "lpv_map_controller.py"


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(f"gen_{abs(hash(str(path))):x}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.skipif(not pl.DEFAULT_ARTIFACT.is_file(), reason="no shipped default design")
def test_regenerating_default_module_gives_identical_bytes(tmp_path):
    paths, skipped = pl.generate(pl.DEFAULT_ARTIFACT, "python", tmp_path)
    assert not skipped
    assert paths[0].read_bytes() == COMMITTED.read_bytes()
    # a second run sees the recorded hash and writes nothing
    mtime = paths[0].stat().st_mtime_ns
    _, skipped_again = pl.generate(pl.DEFAULT_ARTIFACT, "python", tmp_path)
    assert skipped_again and paths[0].stat().st_mtime_ns == mtime


def test_committed_module_records_the_shipped_artifact_and_tracks_a_target():
    mod = _load(COMMITTED)
    from synthesis.artifact import load_artifact

    assert mod.ARTIFACT_SHA256 == load_artifact(pl.DEFAULT_ARTIFACT).sha256
    for fixed in (False, True):
        c = mod.Controller(fixed_point=fixed)
        dmap = 0.0
        hist = [0.0] * 400
        for k in range(24000):  # 40 min, nominal patient, +20 mmHg target
            u = c.step(70.0 + dmap, 90.0, 0.55, 150.0, 40.0)
            hist[k % 400] = u
            ud = hist[(k - 400 + 1) % 400] if k >= 400 else 0.0
            a = math.exp(-0.1 / 150.0)
            dmap = a * dmap + 0.55 * (1 - a) * ud
            assert 0.0 <= u <= mod.MAX_RATE_ML_H
        assert abs(dmap - 20.0) < 0.5
