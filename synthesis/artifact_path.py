"""Where the shipped design artifact lives, without loading what reads it.

:mod:`pressor.synthesis.artifact` (numpy, the design model) re-exports :func:`default_artifact_path`;
the command lines that name the path in their ``--help`` import it from here, so that the help
answers before numpy loads.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def default_artifact_path() -> Path:
    """Absolute path of the shipped default design artifact (``synthesis/data/default_design.npz``):
    the one place that names it.

    Returns
    -------
    Path
        The resolved path inside the installed ``pressor.synthesis`` package.
    """
    return Path(str(resources.files("pressor.synthesis") / "data" / "default_design.npz")).resolve()
