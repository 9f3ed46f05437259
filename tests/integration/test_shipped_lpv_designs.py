"""Every named shipped design (``lpv:NAME`` other than the default, which
tests/codegen/test_pipeline_shipped.py covers): its committed module is current for its artifact
and the codegen sources, intact, its tables are what codegen computes now, and the artifact passed
verification with a certificate."""

from __future__ import annotations

from pathlib import Path

import pytest

from pressor.codegen import pipeline as pl
from pressor.codegen.emit_python import module_sha256
from pressor.contracts.module_hash import module_text_sha256
from pressor.runtime.inputs.controller_loader import LPV_DESIGNS
from pressor.synthesis.artifact import load_artifact
from tests.support.generated_currency import assert_same_bytes, table_mismatches

DATA = Path(pl.REPO_ROOT) / "synthesis" / "data"
#: ``lpv:NAME`` -> the artifact its committed module was generated from
ARTIFACTS = {
    "norepinephrine": DATA / "norepinephrine_design.npz",
    "wide-delay": DATA / "wide_delay_design.npz",
    "cautious": DATA / "cautious_design.npz",
    "norepinephrine-cautious": DATA / "norepinephrine_cautious_design.npz",
}


def test_every_named_design_has_an_artifact_here() -> None:
    assert set(ARTIFACTS) == set(LPV_DESIGNS) - {"phenylephrine"}


@pytest.mark.parametrize("name", sorted(ARTIFACTS))
def test_committed_module_is_current_for_its_certified_artifact(name: str) -> None:
    module, artifact = LPV_DESIGNS[name], ARTIFACTS[name]
    text = module.read_text(encoding="utf-8")
    design = pl.load_design(artifact)
    assert f"Artifact sha256:  {design.sha256}" in text
    assert pl.recorded_hash(module) == pl.content_hash(design.sha256, "python", "q31", 0.1)
    assert module_sha256(text) == module_text_sha256(text)
    verification = load_artifact(artifact).metadata["verification"]
    assert verification["passed"] is True and verification["analysis_lmi"]["certified"] is True


@pytest.mark.parametrize("name", sorted(ARTIFACTS))
def test_committed_tables_equal_tables_regenerated_at_corner_and_seeded_nodes(name: str) -> None:
    checked, mismatches = table_mismatches(LPV_DESIGNS[name], ARTIFACTS[name])
    assert checked >= 30
    assert not mismatches, f"{len(mismatches)} of {checked} nodes differ; first: {mismatches[0]}"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ARTIFACTS))
def test_regenerating_named_design_module_gives_identical_bytes(name: str, tmp_path: Path) -> None:
    paths, skipped = pl.generate(ARTIFACTS[name], "python", tmp_path)
    assert not skipped
    assert_same_bytes(paths[0], LPV_DESIGNS[name])
