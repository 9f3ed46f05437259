"""``pressor verify``: :mod:`pressor.synthesis.verify_cli` with the runtime's plugin loader.

``synthesis`` may not import ``runtime`` (docs/ARCHITECTURE.md), so ``pressor verify
--controller SPEC`` gets its plugin from here: :func:`load_plugin` resolves the spec with
:mod:`pressor.runtime.inputs.controller_plugin` and hands the instance to the synthesis side, which checks
its nominal step (:mod:`pressor.synthesis.verification.plugin`). Without ``--controller`` this is the
artifact verification, unchanged.
"""

from __future__ import annotations

from pressor.contracts.controller import Controller


def load_plugin(spec: str, sample_period_s: float) -> Controller:
    """A checked instance of the plugin ``spec`` at the loop period ``sample_period_s`` (s).

    Raises
    ------
    ValueError
        (:class:`pressor.runtime.inputs.controller_loader.ControllerSpecError`) ``spec`` is not a plugin -
        the shipped controllers are checked by ``pressor verify [ARTIFACT]`` - or the plugin cannot
        be loaded (naming module, class and what is missing).
    """
    from pressor.runtime.inputs.controller_loader import ControllerSpecError
    from pressor.runtime.inputs.controller_plugin import is_plugin_spec, load_plugin_controller

    if not is_plugin_spec(spec):
        raise ControllerSpecError(
            f"--controller {spec!r}: pressor verify --controller takes a plugin"
            " (MODULE:CLASS[:ARGS], FILE.py:CLASS[:ARGS] or an installed 'pressor.controllers'"
            " entry point); the shipped LPV is verified from its artifact (pressor verify"
            " [ARTIFACT]), whose nominal step also runs the PI and the Smith predictor"
        )
    return load_plugin_controller(spec, sample_period_s)


def main(command: str, argv: list[str]) -> int:
    """Entry point used by the ``pressor`` dispatcher; returns the exit code."""
    from pressor.synthesis.verify_cli import main as verify_main

    return verify_main(command, argv, load_plugin=load_plugin)
