"""Package layout: one import namespace, ``pressor``, over the design's top-level folders.

The repository keeps the stages where the design names them (``runtime/``, ``codegen/``,
``synthesis/``, ``hil_sim/``, ...), and a wheel installs them as subpackages of ``pressor`` only
(``pressor.runtime`` from ``runtime/``, ...), so installing pressor writes no generic top-level
name into site-packages. Everything else (name, dependencies, scripts) is in ``pyproject.toml``;
``tests/test_packaging.py`` builds the wheel and checks what it installs.
"""

from setuptools import find_namespace_packages, setup

#: the folders installed as ``pressor.<folder>``, in the order of the layers (docs/ARCHITECTURE.md)
STAGES = (
    "contracts",
    "plumbing",
    "baselines",
    "link",
    "synthesis",
    "codegen",
    "runtime",
    "hil_sim",
)


def subpackages(folder: str) -> list[str]:
    """Every folder under ``folder`` that holds code or data (``synthesis/data`` has no __init__)."""
    return find_namespace_packages(folder, exclude=["__pycache__", "*.__pycache__"])


packages = ["pressor", *(f"pressor.{sub}" for sub in subpackages("pressor"))]
package_dir = {"pressor": "pressor"}
for stage in STAGES:
    package_dir[f"pressor.{stage}"] = stage
    packages += [f"pressor.{stage}", *(f"pressor.{stage}.{sub}" for sub in subpackages(stage))]

setup(packages=packages, package_dir=package_dir)
