"""Generate the shipped Smith law's module on a box no certificate covers (research only).

Usage::

    python -m research.uncertified_module research/designs/wide_delay.toml --out wide_delay

``pressor synth`` writes an artifact only when the Wirtinger analysis certifies the design, and the
analysis does not certify the shipped law with delays much beyond 45 s (docs/notes/estimation.md, "The
frontier, revisited"). To measure what such a box would be worth before a certificate exists, this
runs codegen's own stages (:func:`pressor.codegen.pipeline.tabulate`, ``quantise``, ``emit``) on the
closed-form law ``SmithLPV(loop_gain, Ω, Λ).at(ρ)`` of the config, with no analysis at all. The
module's "Generated with" line starts with ``UNCERTIFIED`` and its ``ARTIFACT_SHA256`` is the
sha256 of the config file (there is no artifact). The runtime's loader refuses such a module
(:data:`pressor.runtime.inputs.controller_loader.UNCERTIFIED_MARK`) unless the caller passes
``allow_uncertified=True``, which only :mod:`research.schedule_sources` does: it must never drive
a pump.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

from pressor.codegen.pipeline import MODULE_NAME, LoadedDesign, emit, quantise, tabulate
from pressor.codegen.pipeline import _display as shown_path  # a path as generation commands show it
from pressor.plumbing.files import write_atomic
from pressor.runtime.inputs.controller_loader import UNCERTIFIED_MARK
from pressor.synthesis.families.smith.law import SmithLPV
from pressor.synthesis.problem.config_toml import load_config
from pressor.synthesis.problem.reconstruct import DelayedController


def uncertified_design(config_path: Path) -> LoadedDesign:
    """Codegen's stage-1 input for the config's Smith law, without an artifact or a certificate.

    Raises
    ------
    ValueError
        The config's controller family is not ``smith``.
    """
    cfg = load_config(config_path)
    if cfg.controller.structure != "smith" or cfg.controller.loop_gain is None:
        raise ValueError(f"{config_path}: field 'controller.structure' must be 'smith'")
    model = cfg.model
    law = SmithLPV(cfg.controller.loop_gain, model.omega, model.lambda_)

    def controller_at(rho: np.ndarray) -> DelayedController:
        r = np.asarray(rho, dtype=float)
        s = law.at(r)
        return DelayedController(
            Ak=s.Ak, Adk=s.Adk, Bk=s.Bk, Ck=s.Ck, Cdk=s.Cdk, Dk=s.Dk, rho=r, tau_s=float(r[2])
        )

    ref = cfg.reference
    return LoadedDesign(
        sha256=hashlib.sha256(config_path.read_bytes()).hexdigest(),
        # the generation command becomes "pressor codegen UNCERTIFIED <config> ...": the mark
        display_path=UNCERTIFIED_MARK.removeprefix("pressor codegen ") + shown_path(config_path),
        controller_fn=controller_at,
        box=np.asarray(model.box, dtype=float),
        rate_bounds=np.asarray(model.rate_bounds, dtype=float),
        omega=float(model.omega),
        lambda_=float(model.lambda_),
        max_rate_ml_h=float(model.max_rate_ml_h),
        synthesis_counts=cfg.grid_points,
        reference=(ref.lambda_s, ref.pump_fraction, ref.k_min) if ref.enabled else None,
        drug=cfg.drug,
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("config", type=Path, help="design TOML of the smith family")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    args = p.parse_args(argv)
    design = uncertified_design(args.config)
    proof = tabulate(design)
    files = emit(design, proof, quantise(design, proof, "q31"), "python")
    path = args.out / f"{MODULE_NAME}.py"
    args.out.mkdir(parents=True, exist_ok=True)
    write_atomic(path, files.files[path.name].encode())
    print(f"wrote {path} (UNCERTIFIED: research only)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
