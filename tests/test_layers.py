"""The arrows between pressor's packages point one way (docs/ARCHITECTURE.md).

The allowed arrows are written once, in :data:`ALLOWED`; every module of every package is parsed and
each of its imports, function-local ones included, must land in its own package, in an allowed one,
or outside the project. A new package has to be added here, with its arrows, before it can ship.
Inside ``runtime`` the same holds between its subpackages and top-level modules
(:data:`RUNTIME_ALLOWED`): core at the bottom, the shipped path's entry points on top.
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


#: runtime's subpackage or top-level module -> the others of runtime it may import (besides itself)
RUNTIME_ALLOWED: dict[str, frozenset[str]] = {
    "generated": frozenset(),
    "core": frozenset(),
    "estimation": frozenset({"core", "generated"}),
    "record": frozenset({"core"}),
    "shell": frozenset({"core", "record"}),
    "inputs": frozenset({"core", "estimation", "shell"}),
    "summary": frozenset({"core", "inputs", "shell"}),
    "session": frozenset({"core", "estimation", "inputs", "record", "shell", "summary"}),
    "cli": frozenset({"core", "inputs", "session", "summary"}),
    "__init__": frozenset(),
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


def runtime_part(path: Path) -> str:
    """The node of :data:`RUNTIME_ALLOWED` a file of ``runtime`` belongs to: its subpackage, or
    the stem of a top-level module."""
    first = path.relative_to(ROOT / "runtime").parts[0]
    return first.removesuffix(".py")


def runtime_targets(path: Path) -> set[str]:
    """The parts of ``runtime`` that ``path`` imports, at any depth of the syntax tree
    (``runtime.core.supervisor`` -> ``core``; ``from runtime import session`` -> ``session``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    modules: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            modules += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "runtime":
                modules += [f"runtime.{alias.name}" for alias in node.names]
            else:
                modules.append(node.module)
    return {m.split(".")[1] for m in modules if m.startswith("runtime.")}


def runtime_violations() -> list[str]:
    """``module -> part`` lines that break :data:`RUNTIME_ALLOWED`."""
    found = []
    for path in package_modules("runtime"):
        part = runtime_part(path)
        allowed = RUNTIME_ALLOWED.get(part, frozenset()) | {part}
        rel = path.relative_to(ROOT).as_posix()
        found += [f"{rel} -> {t}" for t in sorted(runtime_targets(path) - allowed)]
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


def test_every_part_of_runtime_has_its_arrows_written_down_and_they_form_no_cycle():
    parts = {runtime_part(p) for p in package_modules("runtime")}
    assert parts == set(RUNTIME_ALLOWED)
    order: list[str] = []
    pending = dict(RUNTIME_ALLOWED)
    while pending:  # peel off the parts whose arrows all land on parts already placed
        ready = sorted(p for p, deps in pending.items() if deps <= set(order))
        assert ready, f"cycle among {sorted(pending)}"
        order += ready
        for p in ready:
            del pending[p]


def test_runtime_subpackages_import_only_downward():
    assert runtime_violations() == []


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_along_the_allowed_arrows(package):
    assert violations(package) == []


def test_the_import_scan_sees_function_local_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from synthesis.lmi import x\n    import hil_sim.world\n")
    assert imported_top_levels(module) == {"synthesis", "hil_sim"}


def test_the_runtime_scan_sees_function_local_and_from_runtime_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("from runtime import session\ndef f():\n    import runtime.shell.loop\n")
    assert runtime_targets(module) == {"session", "shell"}
