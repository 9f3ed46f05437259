"""Is a committed generated module what codegen generates now? Checks on what is generated (the
tables), not only on its inputs (the artifact and source hashes the header records).

* :func:`table_mismatches` regenerates the tables at a few nodes of a committed module's own grid
  and compares them with the module's ``_TF`` and ``_TQ`` rows exactly: cheap enough for the default
  suite, and it fails on any CPU where the discretisation's bits differ from the committed ones.
* :func:`assert_same_bytes` compares a fully regenerated file with the committed one by sha256 first
  and fails with a short message (counts and the first differing line), never a string diff.
* :func:`node_matrices_digest` hashes the increment matrices of seeded nodes, for comparing
  processes that run different BLAS kernels.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from pressor.codegen import pipeline as pl
from pressor.codegen.discretise import discretise_node
from tests.support.codegen_helpers import load_module

#: Characters of a differing line shown in a failure message.
SHOWN_CHARS = 120


def sampled_nodes(counts: tuple[int, int, int], n_random: int, seed: int) -> list[int]:
    """Flat (C-order) indices of the 8 grid corners and ``n_random`` seeded other nodes."""
    total = int(np.prod(counts))
    corners = {
        int(np.ravel_multi_index((i, j, k), counts))
        for i in (0, counts[0] - 1)
        for j in (0, counts[1] - 1)
        for k in (0, counts[2] - 1)
    }
    rng = np.random.default_rng(seed)
    picked = rng.choice(total, size=min(n_random, total), replace=False)
    return sorted(corners | {int(f) for f in picked})


def table_mismatches(
    module_path: Path, artifact: Path, n_random: int = 24, seed: int = 0
) -> tuple[int, list[str]]:
    """Regenerate the committed module's tables at its grid corners and seeded nodes.

    Each node's increment matrix is discretised from the artifact at the module's own node (exact
    literals, so the same rho the generator used) and scaled and quantised with the module's own
    state scales and row shifts (powers of two: exact), as :func:`pressor.codegen.fixed_point.make_plan`
    does.

    Returns
    -------
    (checked, mismatches)
        Number of nodes checked, and one line per differing node (flat index, rho, first differing
        entry with both values).
    """
    mod = load_module(module_path)
    design = pl.load_design(artifact)
    counts = tuple(int(c) for c in mod.GRID_COUNTS)
    nk = int(mod.N_K)
    scale = np.asarray(mod.STATE_SCALE, dtype=float)
    col_scale = np.concatenate([scale, scale[:nk], [float(mod.E_LIM_MMHG)]])
    shifts = np.asarray(mod.Q_FORMATS["row_shift"], dtype=float)
    nodes = sampled_nodes(counts, n_random, seed)  # type: ignore[arg-type]
    out = []
    for flat in nodes:
        idx = np.unravel_index(flat, counts)
        rho = tuple(float(mod.GRID_NODES[a][int(idx[a])]) for a in range(3))
        m = discretise_node(
            design.controller_fn(np.asarray(rho)),
            design.omega,
            design.lambda_,
            float(mod.SAMPLE_PERIOD_S),
        )
        scaled = (m * col_scale[None, :] / scale[:, None])[: nk + 1]
        q = np.rint(scaled * (2.0**shifts)[:, None]).astype(np.int64)
        got_f = tuple(float(scaled[i, j]) for i, j in mod._ENTRIES)
        got_q = tuple(int(q[i, j]) for i, j in mod._ENTRIES)
        for name, got, want in (("_TF", got_f, mod._TF[flat]), ("_TQ", got_q, mod._TQ[flat])):
            if got != tuple(want):
                e = next(n for n, (a, b) in enumerate(zip(got, want, strict=True)) if a != b)
                out.append(
                    f"{name} node {flat} rho {rho}: entry {mod._ENTRIES[e]} committed "
                    f"{want[e]!r}, regenerated {got[e]!r}"
                )
    return len(nodes), out


def assert_same_bytes(generated: Path, committed: Path) -> None:
    """Fail, in a few lines, unless ``generated`` has exactly ``committed``'s bytes.

    The sha256 digests are compared first; only on a mismatch are the lines compared, to report
    how many differ and the first of them (truncated to :data:`SHOWN_CHARS` characters).
    """
    got, want = generated.read_bytes(), committed.read_bytes()
    got_sha, want_sha = hashlib.sha256(got).hexdigest(), hashlib.sha256(want).hexdigest()
    if got_sha == want_sha:
        return
    got_lines = got.decode("utf-8", "replace").splitlines()
    want_lines = want.decode("utf-8", "replace").splitlines()
    n = max(len(got_lines), len(want_lines))
    differing = [
        i
        for i in range(n)
        if (got_lines[i] if i < len(got_lines) else None)
        != (want_lines[i] if i < len(want_lines) else None)
    ]
    first = differing[0] if differing else 0  # no differing line: only line endings differ

    def show(lines: list[str]) -> str:
        return lines[first][:SHOWN_CHARS] if first < len(lines) else "<end of file>"

    pytest.fail(
        f"{committed.name}: regenerated sha256 {got_sha[:16]}... != committed {want_sha[:16]}...; "
        f"{len(differing)} of {n} lines differ ({len(got_lines)} regenerated, {len(want_lines)} "
        f"committed); first at line {first + 1}:\n"
        f"  committed:   {show(want_lines)}\n"
        f"  regenerated: {show(got_lines)}",
        pytrace=False,
    )


def node_matrices_digest(artifact: Path, n: int = 64, seed: int = 0) -> str:
    """sha256 of the increment matrices at ``n`` seeded points of the artifact's box (Ts 0.1 s)."""
    design = pl.load_design(artifact)
    rng = np.random.default_rng(seed)
    box = design.box
    h = hashlib.sha256()
    for u in rng.random((n, 3)):
        rho = box[:, 0] + u * (box[:, 1] - box[:, 0])
        m = discretise_node(design.controller_fn(rho), design.omega, design.lambda_, 0.1)
        h.update(np.ascontiguousarray(m, dtype="<f8").tobytes())
    return h.hexdigest()
