"""Artifact save/load: round trip, and every kind of damage is a clear ArtifactError."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis.artifact import (
    ArtifactError,
    default_artifact_path,
    load_artifact,
    make_artifact,
    save_artifact,
    with_verification,
)
from pressor.synthesis.problem.config import NOMINAL_RHO


@pytest.fixture(scope="module")
def shipped():
    return load_artifact(default_artifact_path())


def _damaged(artifact, tmp_path: Path, entry: str, change) -> Path:
    """Save ``artifact``, then copy it with ``change(array)`` replacing one entry (None deletes)."""
    src = save_artifact(artifact, tmp_path / "a.npz")
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    new = change(arrays[entry])
    if new is None:
        del arrays[entry]
    else:
        arrays[entry] = new
    dst = tmp_path / "b.npz"
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)
    return dst


def _with_first(a: np.ndarray, value) -> np.ndarray:
    """A copy of a node table with its first element set to ``value``."""
    a = a.copy()
    a[0, 0, 0, 0, 0] = value
    return a


def test_shipped_default_loads_and_its_box_contains_the_nominal_plant(shipped):
    assert shipped.metadata["format_version"] == 1
    for i, v in enumerate(NOMINAL_RHO):
        assert shipped.box[i, 0] <= v <= shipped.box[i, 1]
    assert shipped.gamma > 0 and shipped.omega > 0 and shipped.lambda_ > 0
    assert [g.size for g in shipped.grid] == list(shipped.nodes["Ak"].shape[:3])


def test_round_trip_preserves_content_and_hash(shipped, tmp_path):
    p = save_artifact(shipped, tmp_path / "a.npz")
    back = load_artifact(p)
    assert back.sha256 == shipped.sha256
    assert back.metadata == shipped.metadata
    for k, v in shipped.nodes.items():
        np.testing.assert_array_equal(back.nodes[k], v)


def test_save_is_atomic_and_leaves_no_temporary_files(shipped, tmp_path):
    target = tmp_path / "sub" / "a.npz"
    save_artifact(shipped, target)
    save_artifact(shipped, target)  # replace in place
    assert sorted(p.name for p in target.parent.iterdir()) == ["a.npz"]


def test_truncated_file_names_the_file(shipped, tmp_path):
    p = save_artifact(shipped, tmp_path / "a.npz")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(ArtifactError) as exc:
        load_artifact(p)
    assert str(p) in str(exc.value)


def test_tampered_controller_entry_fails_the_hash_check(shipped, tmp_path):
    dst = _damaged(shipped, tmp_path, "node_Dk", lambda a: _with_first(a, a[0, 0, 0, 0, 0] + 1e-6))
    with pytest.raises(ArtifactError, match="sha256"):
        load_artifact(dst)


def test_nan_in_a_node_table_names_the_field(shipped, tmp_path):
    dst = _damaged(shipped, tmp_path, "node_Ak", lambda a: _with_first(a, np.nan))
    with pytest.raises(ArtifactError, match="node_Ak.*NaN"):
        load_artifact(dst)


def test_missing_entry_names_the_field(shipped, tmp_path):
    dst = _damaged(shipped, tmp_path, "coef_S", lambda a: None)
    with pytest.raises(ArtifactError, match="coef_S.*missing"):
        load_artifact(dst)


def test_wrong_shape_names_the_field(shipped, tmp_path):
    dst = _damaged(shipped, tmp_path, "node_Bk", lambda a: a[..., :1])
    with pytest.raises(ArtifactError, match="node_Bk.*shape"):
        load_artifact(dst)


def test_other_format_version_is_rejected(shipped, tmp_path):
    meta = dict(shipped.metadata)
    meta["format_version"] = 99
    raw = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    dst = _damaged(shipped, tmp_path, "metadata", lambda a: raw)
    with pytest.raises(ArtifactError, match="format_version"):
        load_artifact(dst)


def test_garbage_metadata_is_a_clear_error(shipped, tmp_path):
    raw = np.frombuffer(b"{not json", dtype=np.uint8)
    dst = _damaged(shipped, tmp_path, "metadata", lambda a: raw)
    with pytest.raises(ArtifactError, match="metadata.*JSON"):
        load_artifact(dst)


def test_not_a_zip_and_missing_file_are_clear_errors(tmp_path):
    p = tmp_path / "x.npz"
    p.write_bytes(b"hello")
    with pytest.raises(ArtifactError, match="not a readable artifact"):
        load_artifact(p)
    with pytest.raises(ArtifactError, match="no such file"):
        load_artifact(tmp_path / "nope.npz")
    assert not zipfile.is_zipfile(p)


def test_verification_results_change_the_hash_and_survive_a_round_trip(shipped, tmp_path):
    v = with_verification(shipped, {"passed": True, "note": "unit test"})
    assert v.sha256 != shipped.sha256
    back = load_artifact(save_artifact(v, tmp_path / "v.npz"))
    assert back.metadata["verification"] == {"passed": True, "note": "unit test"}


def test_make_artifact_rejects_non_finite_coefficients(shipped):
    coefs = dict(shipped.coefficients)
    coefs["R"] = coefs["R"] * np.inf
    with pytest.raises(ArtifactError, match="coef_R"):
        make_artifact(shipped.metadata, coefs, shipped.nodes)
