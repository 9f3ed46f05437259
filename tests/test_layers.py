"""The arrows between pressor's packages point one way (docs/ARCHITECTURE.md).

The allowed arrows are written once, in :data:`ALLOWED`; every module of every package is parsed and
each of its imports, function-local ones included, must land in its own package, in an allowed one,
or outside the project. A new package has to be added here, with its arrows, before it can ship.

Inside ``synthesis`` the same holds one level down, between its subpackages
(:data:`SYNTHESIS_ALLOWED`, docs/ARCHITECTURE.md).
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


#: part of synthesis -> the parts of synthesis it may import (besides itself). A part is a
#: subpackage (dotted below ``synthesis``) or a top-level module; a module belongs to the longest
#: part that prefixes it. The registry is its own part, at the bottom: it names the families but
#: loads their modules only on lookup (by name), so the config and the artifact can name a family.
SYNTHESIS_ALLOWED: dict[str, frozenset[str]] = {
    "__init__": frozenset(),
    "solver": frozenset(),
    "families": frozenset(),
    "families.registry": frozenset(),
    "problem": frozenset({"families.registry"}),
    "artifact": frozenset({"problem", "families.registry"}),
    "certificates": frozenset({"problem"}),
    "certificates.wirtinger": frozenset({"certificates", "problem", "solver"}),
    "certificates.jensen": frozenset({"certificates", "problem", "solver"}),
    "families.smith": frozenset(
        {"families.registry", "certificates", "certificates.wirtinger", "problem", "artifact"}
    ),
    "families.theorem3": frozenset(
        {
            "families.registry",
            "certificates",
            "certificates.jensen",
            "problem",
            "solver",
            "artifact",
        }
    ),
    "verification": frozenset({"certificates", "problem"}),
    "research": frozenset(
        {
            "artifact",
            "certificates",
            "families.smith",
            "families.theorem3",
            "problem",
            "verification",
        }
    ),
    "cli": frozenset({"artifact", "families.registry", "problem", "solver", "verification"}),
    "verify_cli": frozenset({"artifact", "solver", "verification"}),
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


def synthesis_part(module: str) -> str | None:
    """The :data:`SYNTHESIS_ALLOWED` part holding the dotted ``module`` (None: no part holds it)."""
    parts = module.split(".")
    if parts[0] != "synthesis":
        return None
    if len(parts) == 1:
        return "__init__"
    best = None
    for key in SYNTHESIS_ALLOWED:
        depth = key.count(".") + 1
        if parts[1 : 1 + depth] == key.split(".") and (best is None or depth > best.count(".") + 1):
            best = key
    return best


def is_type_checking_block(node: ast.AST) -> bool:
    """``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``): its imports never run."""
    return isinstance(node, ast.If) and ast.unparse(node.test).split(".")[-1] == "TYPE_CHECKING"


def runtime_synthesis_imports(path: Path) -> set[str]:
    """Dotted synthesis modules ``path`` imports at run time, at any depth (function-local too).

    Imports under ``if TYPE_CHECKING:`` are left out: they only name a type for the annotations
    (this is how the registry and the reconstruction name types from above without loading them).
    ``from synthesis import x`` counts as ``synthesis.x``.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    type_only = {
        id(inner)
        for node in ast.walk(tree)
        if is_type_checking_block(node)
        for stmt in node.body
        for inner in ast.walk(stmt)
    }
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "synthesis")
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] == "synthesis":
                found.update(f"{node.module}.{a.name}" for a in node.names)
    return found


def synthesis_violations() -> list[str]:
    """``module -> imported module`` lines that break :data:`SYNTHESIS_ALLOWED`."""
    found = []
    for path in package_modules("synthesis"):
        rel = path.relative_to(ROOT).with_suffix("")
        module = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        own = synthesis_part(module)
        if own is None:
            found.append(f"{rel.as_posix()}.py: in no part of SYNTHESIS_ALLOWED")
            continue
        for imported in sorted(runtime_synthesis_imports(path)):
            # ``from synthesis.problem import basis`` names synthesis.problem.basis: its part is
            # problem either way; a plain ``import synthesis`` is the front door
            target = synthesis_part(imported)
            if target is not None and target != own and target not in SYNTHESIS_ALLOWED[own]:
                found.append(f"{rel.as_posix()}.py ({own}) -> {imported} ({target})")
    return found


def first_cycle(graph: dict[str, frozenset[str]]) -> str | None:
    """One cycle of ``graph`` as ``a -> b -> a``, or None."""
    visiting: set[str] = set()
    done: set[str] = set()

    def visit(node: str, path: tuple[str, ...]) -> str | None:
        if node in visiting:
            return " -> ".join((*path, node))
        if node in done:
            return None
        visiting.add(node)
        for nxt in sorted(graph[node]):
            cycle = visit(nxt, (*path, node))
            if cycle:
                return cycle
        visiting.discard(node)
        done.add(node)
        return None

    for node in graph:
        cycle = visit(node, ())
        if cycle:
            return cycle
    return None


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


def test_synthesis_subpackage_arrows_form_no_cycle():
    assert all(
        nxt in SYNTHESIS_ALLOWED for targets in SYNTHESIS_ALLOWED.values() for nxt in targets
    )
    assert first_cycle(SYNTHESIS_ALLOWED) is None


def test_synthesis_subpackages_import_only_downward():
    assert synthesis_violations() == []


def test_the_synthesis_scan_skips_only_type_checking_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "from typing import TYPE_CHECKING\n"
        "from synthesis import cli\n"
        "if TYPE_CHECKING:\n    from synthesis.artifact import A\n"
        "def f():\n    import synthesis.research.naive_lmi\n"
    )
    assert runtime_synthesis_imports(module) == {"synthesis.cli", "synthesis.research.naive_lmi"}
    assert synthesis_part("synthesis.research.naive_lmi") == "research"
    assert synthesis_part("synthesis.families.smith.law") == "families.smith"
    assert synthesis_part("synthesis.families.registry.Family") == "families.registry"
