"""The family registry (:mod:`pressor.synthesis.families.registry`): one object per name, every call site
through it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from pressor.synthesis.families.registry import (
    DEFAULT_STRUCTURE,
    ControllerFamily,
    family_named,
    structures,
)

ROOT = Path(__file__).resolve().parents[3]
#: the modules that may name a family: the registry and each family's own modules
FAMILY_MODULES = {
    "synthesis/families/registry.py",
    "synthesis/families/smith/family.py",
    "synthesis/families/smith/design.py",
    "synthesis/families/theorem3/family.py",
}
#: lines that name the Smith-predictor baseline's nominal step in the verify report, not a family
BASELINE_LINES = {
    '"smith": smith,',
    'for name in ("lpv", "pi", "smith"):',
    'for name in ("plugin", "pi", "smith"):',
}
#: a family name as a string literal, or a test of one
NAMES = re.compile(
    r"""is_smith|["'](theorem3|smith)["']\s*[:,)\]=]|==\s*["'](theorem3|smith)["']"""
)


def test_every_registered_name_gives_its_own_object():
    assert DEFAULT_STRUCTURE in structures()
    for name in structures():
        fam = family_named(name)
        assert fam.name == name
        assert fam.controller_order(3) >= 1 and fam.coefficient_shapes(3, 2)


def test_an_unknown_name_is_a_value_error_naming_the_allowed_ones():
    with pytest.raises(ValueError, match=re.escape(str(structures()))):
        family_named("lqr")


def test_the_default_family_is_the_one_of_an_artifact_without_an_entry():
    fam = ControllerFamily.from_metadata({})
    assert fam.is_default and fam.impl is family_named(DEFAULT_STRUCTURE)


def test_loop_gain_only_for_a_family_that_takes_it():
    for name in structures():
        if family_named(name).takes_loop_gain:
            assert ControllerFamily(name, 2.0).loop_gain == 2.0
            with pytest.raises(ValueError, match="loop_gain"):
                ControllerFamily(name, None)
        else:
            with pytest.raises(ValueError, match="loop_gain"):
                ControllerFamily(name, 2.0)


def test_controller_at_goes_through_the_family(monkeypatch):
    from pressor.synthesis.artifact import default_artifact_path, load_artifact
    from pressor.synthesis.problem.reconstruct import controller_at

    art = load_artifact(default_artifact_path())
    seen = []
    impl = type(art.family.impl)
    monkeypatch.setattr(impl, "controller_at", lambda self, a, rho: seen.append(rho) or "law")
    assert controller_at(art, (0.55, 150.0, 40.0)) == "law"
    np.testing.assert_array_equal(seen[0], [0.55, 150.0, 40.0])


def test_no_module_outside_a_family_names_one():
    hits = []
    for pkg in ("synthesis", "codegen"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in FAMILY_MODULES:
                continue
            for i, line in enumerate(path.read_text().splitlines(), 1):
                code = line.split("#")[0]
                if NAMES.search(code) and line.strip() not in BASELINE_LINES:
                    hits.append(f"{rel}:{i}: {line.strip()}")
    assert not hits, hits
