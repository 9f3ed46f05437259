"""The arrows between pressor's packages point one way (docs/ARCHITECTURE.md).

The allowed arrows are written once, in :data:`ALLOWED`; every module of every package is parsed and
each of its imports, function-local ones included, must land in its own package, in an allowed one,
or outside the project. A new package has to be added here, with its arrows, before it can ship.

Inside ``synthesis``, ``runtime`` and ``hil_sim`` the same holds one level down, between their parts
(:data:`INNER_ALLOWED`, docs/ARCHITECTURE.md).

Every package is imported through the one installed namespace, ``pressor`` (``pressor.runtime``
is the folder ``runtime/``; setup.py maps them): an import of a folder's bare name
(``import runtime``) works only inside a checkout and is a violation everywhere.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: package -> the project packages it may import (besides itself)
ALLOWED: dict[str, frozenset[str]] = {
    "plumbing": frozenset(),
    "contracts": frozenset(),
    "baselines": frozenset({"contracts"}),
    "link": frozenset({"plumbing", "contracts"}),
    "synthesis": frozenset({"plumbing", "contracts", "baselines"}),
    "codegen": frozenset({"plumbing", "contracts", "synthesis"}),
    "runtime": frozenset({"plumbing", "contracts", "baselines", "link"}),
    "hil_sim": frozenset({"plumbing", "contracts", "baselines", "link", "runtime"}),
    "pressor": frozenset(
        {"plumbing", "contracts", "baselines", "link", "synthesis", "codegen", "runtime", "hil_sim"}
    ),
}

#: third-party packages a package must never load (the bedside runtime has no solver)
FORBIDDEN_THIRD_PARTY: dict[str, frozenset[str]] = {
    "plumbing": frozenset({"cvxpy", "clarabel", "scipy", "numpy", "serial", "pymavlink", "rerun"}),
    "contracts": frozenset({"cvxpy", "clarabel", "scipy", "serial", "pymavlink", "rerun"}),
    "baselines": frozenset({"cvxpy", "clarabel", "scipy", "numpy", "serial", "pymavlink", "rerun"}),
    "runtime": frozenset({"cvxpy", "clarabel", "scipy"}),
    "link": frozenset({"cvxpy", "clarabel", "scipy", "rerun"}),
}


#: part of synthesis -> the parts of synthesis it may import (besides itself). The registry is its
#: own part, at the bottom: it names the families but loads their modules only on lookup (by
#: name), so the config and the artifact can name a family.
SYNTHESIS_ALLOWED: dict[str, frozenset[str]] = {
    "__init__": frozenset(),
    "solver": frozenset(),
    "families": frozenset(),
    "families.registry": frozenset(),
    # where the shipped artifact lives (standard library only): the CLIs' --help names it
    "artifact_path": frozenset(),
    "problem": frozenset({"families.registry"}),
    "artifact": frozenset({"problem", "families.registry", "artifact_path"}),
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
    "cli": frozenset({"artifact", "families.registry", "problem", "solver", "verification"}),
    "verify_cli": frozenset({"artifact", "artifact_path", "solver", "verification"}),
}

#: part of runtime -> the parts of runtime it may import (besides itself): the per-tick core at
#: the bottom, the shipped path's entry points (session, cli) on top
RUNTIME_ALLOWED: dict[str, frozenset[str]] = {
    "__init__": frozenset(),
    "generated": frozenset(),
    "core": frozenset(),
    "estimation": frozenset({"core", "generated"}),
    "record": frozenset({"core"}),
    "shell": frozenset({"core", "record"}),
    "inputs": frozenset({"core", "estimation", "shell"}),
    "summary": frozenset({"core", "inputs", "shell"}),
    "ending": frozenset({"core", "inputs", "shell", "summary"}),
    "handshake": frozenset({"inputs", "shell"}),
    "session": frozenset(
        {"core", "ending", "estimation", "handshake", "inputs", "record", "shell", "summary"}
    ),
    "cli": frozenset({"core", "inputs", "session", "summary"}),
}

#: part of hil_sim -> the parts of hil_sim it may import (besides itself): patients and the two devices
#: (pump, monitor) at the bottom, scenarios on them, the world on all three, one patient's episode
#: and what the dose limits can hold (``reach``) on the world, trials and the cli on top; the
#: compiled twins (``native``) on the patients, used by trials. The device process is its own part
#: of ``devices``
#: (``devices.device``, ``devices.device_options``): it runs the world, which runs the pump.
HIL_SIM_ALLOWED: dict[str, frozenset[str]] = {
    "__init__": frozenset(),
    "patients": frozenset(),
    "devices": frozenset(),
    "native": frozenset({"patients"}),
    "scenarios": frozenset({"patients", "devices"}),
    "world": frozenset({"patients", "devices", "scenarios"}),
    "reach": frozenset({"patients", "world"}),
    "episode": frozenset({"world"}),
    "devices.device_options": frozenset({"patients", "scenarios", "world"}),
    "devices.device": frozenset({"devices.device_options", "patients", "scenarios"}),
    "trials": frozenset({"episode", "native", "patients", "scenarios", "world"}),
    "cli": frozenset({"patients", "scenarios", "trials"}),
}

#: package -> its parts and their allowed arrows. A part is a subpackage (dotted below the
#: package) or a top-level module; a module belongs to the longest part that prefixes it.
INNER_ALLOWED: dict[str, dict[str, frozenset[str]]] = {
    "synthesis": SYNTHESIS_ALLOWED,
    "runtime": RUNTIME_ALLOWED,
    "hil_sim": HIL_SIM_ALLOWED,
}


#: folders of the checkout that are not installed: the tests, the re-runnable figures and the
#: experiments behind the docs' findings
NOT_INSTALLED = ("tests", "benchmarks", "research")


def project_packages() -> list[str]:
    """Every top-level directory of the checkout that is a Python package (has ``__init__.py``)."""
    return sorted(
        p.name
        for p in ROOT.iterdir()
        if p.is_dir() and (p / "__init__.py").is_file() and p.name not in NOT_INSTALLED
    )


def layer_of(dotted: str) -> str:
    """The package (a key of :data:`ALLOWED`) a dotted import lands in, ``bare:NAME`` for a
    folder imported by its bare name, or the top-level name of a third-party import."""
    parts = dotted.split(".")
    if parts[0] == "pressor":
        return parts[1] if len(parts) > 1 and parts[1] in ALLOWED else "pressor"
    if parts[0] in ALLOWED:
        return f"bare:{parts[0]}"
    return parts[0]


def package_modules(package: str) -> list[Path]:
    """The hand-written and generated ``.py`` files of ``package``."""
    return sorted((ROOT / package).rglob("*.py"))


def imported_layers(path: Path) -> set[str]:
    """:func:`layer_of` every absolute import in ``path``, at any depth of the syntax tree
    (``if TYPE_CHECKING:`` imports included: a package may not even name what it must not load)."""
    return {layer_of(module) for module in imported_modules(path)}


def violations(package: str) -> list[str]:
    """``module -> imported package`` lines that break the allowed arrows of ``package``."""
    ours = set(ALLOWED)
    allowed = ALLOWED[package] | {package}
    banned = FORBIDDEN_THIRD_PARTY.get(package, frozenset())
    found = []
    for path in package_modules(package):
        rel = path.relative_to(ROOT).as_posix()
        for name in sorted(imported_layers(path)):
            if (name in ours and name not in allowed) or name in banned or name.startswith("bare:"):
                found.append(f"{rel} -> {name}")
    return found


def part_of(package: str, module: str) -> str | None:
    """The part of ``package`` (:data:`INNER_ALLOWED`) holding the dotted ``module``; None when
    ``module`` is outside ``package`` or in no part."""
    parts = module.split(".")
    if parts[:2] != ["pressor", package]:
        return None
    parts = parts[1:]
    if len(parts) == 1:
        return "__init__"
    best = None
    for key in INNER_ALLOWED[package]:
        depth = key.count(".") + 1
        if parts[1 : 1 + depth] == key.split(".") and (best is None or depth > best.count(".") + 1):
            best = key
    return best


def is_type_checking_block(node: ast.AST) -> bool:
    """``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``): its imports never run."""
    return isinstance(node, ast.If) and ast.unparse(node.test).split(".")[-1] == "TYPE_CHECKING"


def imported_modules(path: Path, run_time_only: bool = False) -> set[str]:
    """Dotted names of every absolute import in ``path``, at any depth (function-local too);
    ``from a.b import c`` counts as ``a.b.c``. With ``run_time_only``, imports under
    ``if TYPE_CHECKING:`` are left out: they only name a type for the annotations."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    type_only = {
        id(inner)
        for node in ast.walk(tree)
        if run_time_only and is_type_checking_block(node)
        for stmt in node.body
        for inner in ast.walk(stmt)
    }
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def run_time_imports(path: Path, package: str) -> set[str]:
    """Dotted modules of ``package`` that ``path`` imports at run time (:func:`imported_modules`;
    this is how synthesis's registry and reconstruction name types from above without loading
    them). ``from pressor.package import x`` counts as ``pressor.package.x``."""
    return {
        m
        for m in imported_modules(path, run_time_only=True)
        if m.split(".")[:2] == ["pressor", package]
    }


def inner_violations(package: str) -> list[str]:
    """``module -> imported module`` lines that break ``package``'s :data:`INNER_ALLOWED`."""
    allowed = INNER_ALLOWED[package]
    found = []
    for path in package_modules(package):
        rel = path.relative_to(ROOT).with_suffix("")
        module = ".".join(("pressor", *(rel.parts[:-1] if rel.name == "__init__" else rel.parts)))
        own = part_of(package, module)
        if own is None:
            found.append(f"{rel.as_posix()}.py: in no part of {package}'s arrows")
            continue
        for imported in sorted(run_time_imports(path, package)):
            # ``from pressor.synthesis.problem import basis`` names pressor.synthesis.problem.basis:
            # its part is problem either way; a plain ``import pressor.synthesis`` is the front door
            target = part_of(package, imported)
            if target is not None and target != own and target not in allowed[own]:
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
    assert first_cycle(ALLOWED) is None


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_along_the_allowed_arrows(package):
    assert violations(package) == []


def test_the_import_scan_sees_function_local_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "def f():\n    from pressor.synthesis.families.theorem3.lmi import x\n"
        "    import pressor.hil_sim.world\n    from pressor import api\n"
    )
    assert imported_layers(module) == {"synthesis", "hil_sim", "pressor"}


def test_the_import_scan_flags_a_folder_imported_by_its_bare_name(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("import runtime.core\nfrom link import codec\nimport linkage\n")
    assert imported_layers(module) == {"bare:runtime", "bare:link", "linkage"}


def test_setup_installs_every_package_under_the_pressor_namespace():
    tree = ast.parse((ROOT / "setup.py").read_text(encoding="utf-8"))
    stages = next(
        ast.literal_eval(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", None) == "STAGES"
    )
    assert set(stages) == set(ALLOWED) - {"pressor"}


def test_installed_packages_import_no_benchmark_research_or_test_code():
    leaks = [
        f"{path.relative_to(ROOT).as_posix()} -> {name}"
        for package in ALLOWED
        for path in package_modules(package)
        for name in sorted(imported_layers(path))
        if name in NOT_INSTALLED
    ]
    assert leaks == []


def test_research_code_imports_nothing_from_benchmarks():
    # one way only: a benchmark may use research code (the straightforward formulations its
    # synthesis figures are ratios against, the device's step fit), never the reverse
    back = [
        f"{path.relative_to(ROOT).as_posix()} -> {module}"
        for path in sorted((ROOT / "research").rglob("*.py"))
        for module in sorted(imported_modules(path))
        if module.split(".")[0] == "benchmarks"
    ]
    assert back == []


@pytest.mark.parametrize("folder", ["tests", "benchmarks", "research", "examples", "scripts"])
def test_code_outside_the_packages_imports_them_through_pressor(folder):
    bare = [
        f"{path.relative_to(ROOT).as_posix()} -> {name}"
        for path in sorted((ROOT / folder).rglob("*.py"))
        for name in sorted(imported_layers(path))
        if name.startswith("bare:")
    ]
    assert bare == []


@pytest.mark.parametrize("package", sorted(INNER_ALLOWED))
def test_the_arrows_between_a_packages_parts_form_no_cycle(package):
    graph = INNER_ALLOWED[package]
    assert all(nxt in graph for targets in graph.values() for nxt in targets)
    assert first_cycle(graph) is None


@pytest.mark.parametrize("package", sorted(INNER_ALLOWED))
def test_a_packages_parts_import_only_downward(package):
    assert inner_violations(package) == []


def test_the_inner_scan_skips_only_type_checking_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "from typing import TYPE_CHECKING\n"
        "from pressor.synthesis import cli\n"
        "if TYPE_CHECKING:\n    from pressor.synthesis.artifact import A\n"
        "def f():\n    import pressor.synthesis.families.smith.law\n"
    )
    assert run_time_imports(module, "synthesis") == {
        "pressor.synthesis.cli",
        "pressor.synthesis.families.smith.law",
    }
    assert part_of("synthesis", "pressor.synthesis.families.smith.law") == "families.smith"
    assert part_of("synthesis", "pressor.synthesis.families.registry.Family") == "families.registry"
    assert part_of("runtime", "pressor.runtime.shell.loop.Loop") == "shell"
    assert part_of("runtime", "pressor.runtime.session") == "session"
    assert part_of("hil_sim", "pressor.hil_sim.devices.pump") == "devices"
    assert part_of("hil_sim", "pressor.hil_sim.devices.device_options") == "devices.device_options"
    assert part_of("hil_sim", "pressor.hil_sim.episode.simulate") == "episode"
