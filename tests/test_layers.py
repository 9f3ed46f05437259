"""The arrows between pressor's packages point one way (docs/ARCHITECTURE.md).

The allowed arrows are written once, in :data:`ALLOWED`; every module of every package is parsed and
each of its imports, function-local ones included, must land in its own package, in an allowed one,
or outside the project. A new package has to be added here, with its arrows, before it can ship.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: package -> the project packages it may import (besides itself)
ALLOWED: dict[str, frozenset[str]] = {
    "contracts": frozenset(),
    "baselines": frozenset({"contracts"}),
    "link": frozenset({"contracts"}),
    "synthesis": frozenset({"contracts", "baselines"}),
    "codegen": frozenset({"contracts", "synthesis"}),
    "runtime": frozenset({"contracts", "baselines", "link"}),
    "hil_sim": frozenset({"contracts", "baselines", "link", "runtime"}),
    "pressor": frozenset(
        {"contracts", "baselines", "link", "synthesis", "codegen", "runtime", "hil_sim"}
    ),
}

#: third-party packages a package must never load (the bedside runtime has no solver)
FORBIDDEN_THIRD_PARTY: dict[str, frozenset[str]] = {
    "contracts": frozenset({"cvxpy", "clarabel", "scipy", "serial", "pymavlink", "rerun"}),
    "baselines": frozenset({"cvxpy", "clarabel", "scipy", "numpy", "serial", "pymavlink", "rerun"}),
    "runtime": frozenset({"cvxpy", "clarabel", "scipy"}),
    "link": frozenset({"cvxpy", "clarabel", "scipy", "rerun"}),
}


def project_packages() -> list[str]:
    """Every top-level directory of the checkout that is a Python package (has ``__init__.py``)."""
    return sorted(
        p.name
        for p in ROOT.iterdir()
        if p.is_dir() and (p / "__init__.py").is_file() and p.name not in ("tests", "benchmarks")
    )


def package_modules(package: str) -> list[Path]:
    """The hand-written and generated ``.py`` files of ``package``."""
    return sorted((ROOT / package).rglob("*.py"))


def imported_top_levels(path: Path) -> set[str]:
    """Top-level names of every absolute import in ``path``, at any depth of the syntax tree."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def violations(package: str) -> list[str]:
    """``module -> imported package`` lines that break the allowed arrows of ``package``."""
    ours = set(ALLOWED)
    allowed = ALLOWED[package] | {package}
    banned = FORBIDDEN_THIRD_PARTY.get(package, frozenset())
    found = []
    for path in package_modules(package):
        rel = path.relative_to(ROOT).as_posix()
        for name in sorted(imported_top_levels(path)):
            if (name in ours and name not in allowed) or name in banned:
                found.append(f"{rel} -> {name}")
    return found


def test_every_package_of_the_checkout_has_its_arrows_written_down():
    assert set(project_packages()) == set(ALLOWED)


def test_the_allowed_arrows_form_no_cycle():
    visiting: set[str] = set()
    done: set[str] = set()

    def visit(node: str, path: tuple[str, ...]) -> None:
        assert node not in visiting, f"cycle: {' -> '.join((*path, node))}"
        if node in done:
            return
        visiting.add(node)
        for nxt in ALLOWED[node]:
            visit(nxt, (*path, node))
        visiting.discard(node)
        done.add(node)

    for package in ALLOWED:
        visit(package, ())


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_along_the_allowed_arrows(package):
    assert violations(package) == []


def test_the_import_scan_sees_function_local_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "def f():\n    from synthesis.families.theorem3.lmi import x\n    import hil_sim.world\n"
    )
    assert imported_top_levels(module) == {"synthesis", "hil_sim"}
