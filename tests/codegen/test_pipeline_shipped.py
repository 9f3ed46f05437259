"""Codegen on the SHIPPED design (whatever synthesis/data/default_design.npz holds): the committed
module is current and intact, and the generated Python/C agree with each other, with the float
reference and with the exactly reconstructed controller. Also tamper detection and CLI errors."""

from __future__ import annotations

import hashlib
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pressor.codegen import pipeline as pl
from pressor.codegen.discretise import discretise_node
from pressor.codegen.emit_python import module_sha256
from pressor.codegen.frozen_loop import frozen_loop_matrices, unstable_root_count
from pressor.codegen.tables import interpolate
from pressor.contracts.module_hash import module_text_sha256
from pressor.runtime.inputs.controller_loader import ControllerSpecError, load_controller
from tests.support.codegen_helpers import (
    CController,
    continuous_reference,
    fopdt_closed_loop,
    load_module,
    random_inputs,
)
from tests.support.generated_currency import assert_same_bytes, table_mismatches

COMMITTED = Path(pl.REPO_ROOT) / "runtime" / "generated" / "lpv_map_controller.py"
#: the double-precision C twin the in-process simulator steps (pressor.hil_sim.native.controller)
COMMITTED_C = [COMMITTED.with_suffix(".h"), COMMITTED.with_suffix(".c")]
pytestmark = pytest.mark.skipif(not pl.DEFAULT_ARTIFACT.is_file(), reason="no shipped design")


def _shipped_sha256() -> str:
    return pl.load_design(pl.DEFAULT_ARTIFACT).sha256


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """The shipped artifact through every stage once: proof, q31 module, q31 C library."""
    design = pl.load_design(pl.DEFAULT_ARTIFACT)
    proof = pl.tabulate(design)
    plan = pl.quantise(design, proof, "q31")
    root = tmp_path_factory.mktemp("shipped")
    src = pl.emit(design, proof, plan, "python").files["lpv_map_controller.py"]
    (root / "lpv_map_controller.py").write_text(src, encoding="utf-8")
    out = {"design": design, "proof": proof, "mod": load_module(root / "lpv_map_controller.py"),
           "src": src, "root": root}  # fmt: skip
    gcc = shutil.which("gcc")
    if gcc:
        for name, text in pl.emit(design, proof, plan, "c").files.items():
            (root / name).write_text(text)
        lib = root / "libctl.so"
        subprocess.run(
            [gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-shared",
             "-fPIC", "-o", str(lib), str(root / "lpv_map_controller.c")],
            check=True, capture_output=True, text=True,
        )  # fmt: skip
        out["lib"] = lib
    return out


def test_committed_module_is_current_for_shipped_artifact_and_codegen_sources():
    text = COMMITTED.read_text(encoding="utf-8")
    design = pl.load_design(pl.DEFAULT_ARTIFACT)
    assert f"Artifact sha256:  {design.sha256}" in text
    assert pl.recorded_hash(COMMITTED) == pl.content_hash(design.sha256, "python", "q31", 0.1)


def test_committed_c_twin_is_current_for_shipped_artifact_and_codegen_sources():
    design = pl.load_design(pl.DEFAULT_ARTIFACT)
    for path in COMMITTED_C:
        assert f"Artifact sha256:  {design.sha256}" in path.read_text(encoding="utf-8")
        assert pl.recorded_hash(path) == pl.content_hash(design.sha256, "c-float", "q31", 0.1)


def test_committed_module_self_hash_matches_its_text():
    text = COMMITTED.read_text(encoding="utf-8")
    assert module_sha256(text) == module_text_sha256(text)
    assert f"MODULE_SHA256 = '{module_sha256(text)}'" in text


def test_committed_tables_equal_tables_regenerated_at_corner_and_seeded_nodes():
    """What is generated, not only its inputs: the header hashes above would not notice a
    discretisation whose bits changed with the CPU (1075 coefficients did, by up to 4 ulp)."""
    checked, mismatches = table_mismatches(COMMITTED, pl.DEFAULT_ARTIFACT)
    assert checked >= 30
    assert not mismatches, f"{len(mismatches)} of {checked} nodes differ; first: {mismatches[0]}"


@pytest.mark.slow
def test_regenerating_default_module_gives_identical_bytes(tmp_path):
    paths, skipped = pl.generate(pl.DEFAULT_ARTIFACT, "python", tmp_path)
    assert not skipped
    assert_same_bytes(paths[0], COMMITTED)
    mtime = paths[0].stat().st_mtime_ns
    _, skipped_again = pl.generate(pl.DEFAULT_ARTIFACT, "python", tmp_path)
    assert skipped_again and paths[0].stat().st_mtime_ns == mtime
    c_paths, _ = pl.generate(pl.DEFAULT_ARTIFACT, "c", tmp_path, c_float=True)
    assert [p.name for p in c_paths] == [p.name for p in COMMITTED_C]
    for generated, committed in zip(c_paths, COMMITTED_C, strict=True):
        assert_same_bytes(generated, committed)


def test_loader_accepts_intact_module_and_checks_artifact_sha():
    c = load_controller("lpv", artifact_sha256=_shipped_sha256())
    assert 0.0 <= c.step(80.0, 90.0, 0.5, 150.0, 30.0) <= c.max_rate_ml_h


@pytest.mark.parametrize("how", ["edit", "truncate", "append"])
def test_loader_refuses_tampered_module_naming_the_file(tmp_path, how):
    text = COMMITTED.read_text(encoding="utf-8")
    bad = tmp_path / "lpv_map_controller.py"
    if how == "edit":  # one coefficient digit changed
        k = text.index("_TQ = (") + 20
        d = text[k]
        text = text[:k] + ("1" if d != "1" else "2") + text[k + 1 :]
    elif how == "truncate":
        text = text[: len(text) // 2]
    else:
        text += "\nMAX_RATE_ML_H = 1e9\n"
    bad.write_text(text, encoding="utf-8")
    with pytest.raises(ControllerSpecError, match=str(bad.name)) as exc:
        load_controller(str(bad))
    assert "MODULE_SHA256" in str(exc.value)


def test_loader_refuses_module_for_another_artifact(tmp_path):
    text = COMMITTED.read_text(encoding="utf-8")
    old = text.split("ARTIFACT_SHA256 = '")[1][:64]
    other = text.replace(old, hashlib.sha256(b"other").hexdigest())
    other = other.replace(module_sha256(text), module_sha256(other))
    p = tmp_path / "m.py"
    p.write_text(other, encoding="utf-8")
    load_controller(str(p))  # intact, so it loads without an artifact to compare with
    with pytest.raises(ControllerSpecError, match="ARTIFACT_SHA256"):
        load_controller(str(p), artifact_sha256=_shipped_sha256())


def test_shipped_integer_python_matches_compiled_c_bit_exact(shipped):
    if "lib" not in shipped:
        pytest.skip("no gcc")
    py = shipped["mod"].Controller(fixed_point=True)
    c = CController(shipped["lib"])
    for args in random_inputs(21, 6000):
        a, b = py.step(*args), c.step(*args)
        assert a == b, (args, a, b)


def test_shipped_fixed_point_within_stated_budget_of_float_over_1h_closed_loop(shipped):
    mod = shipped["mod"]
    uf = fopdt_closed_loop(mod.Controller(), 3600.0, seed=2)
    uq = fopdt_closed_loop(mod.Controller(fixed_point=True), 3600.0, seed=2)
    err = max(abs(a - b) for a, b in zip(uf, uq, strict=True))
    assert err <= mod.FIXED_VS_FLOAT_BUDGET_ML_H, err
    assert max(uf) > 5.0


def test_shipped_offgrid_midpoints_within_bound_and_frozen_loops_stable(shipped):
    """Recomputed here (not read from the proof): every 7th cell midpoint plus seeded points."""
    design, proof = shipped["design"], shipped["proof"]
    mids = proof.grid.cell_midpoints()[::7]
    rng = np.random.default_rng(99)
    pts = np.vstack([mids, design.box[:, 0] + rng.random((4, 3)) * np.ptp(design.box, 1)])
    for rho in pts:
        exact = discretise_node(design.controller_fn(rho), design.omega, design.lambda_, 0.1)
        approx = interpolate(proof.tables, proof.grid, rho)
        num = np.linalg.norm(approx - exact, axis=1)
        den = np.maximum(np.linalg.norm(exact, axis=1), 1e-300)
        assert float(np.max(num / den)) <= pl.OFFGRID_REL_TOL, rho
        assert unstable_root_count(frozen_loop_matrices(approx, rho, 0.1)) == 0, rho


def test_shipped_time_varying_loop_at_rate_bounds_stays_bounded_and_settles(shipped):
    mod, box, rates = shipped["mod"], shipped["design"].box, shipped["design"].rate_bounds

    def tri(t, lo, hi, rate):
        span = hi - lo
        p = (t * rate) % (2 * span)
        return lo + (p if p < span else 2 * span - p)

    def rho(t):
        return tuple(tri(t, box[i, 0], box[i, 1], rates[i]) for i in range(3))

    cmds = fopdt_closed_loop(mod.Controller(), 3600.0, seed=8, rho_fn=rho)
    tail = cmds[-3000:]
    assert all(math.isfinite(u) and 0.0 <= u <= mod.MAX_RATE_ML_H for u in cmds)
    assert max(tail) - min(tail) < 30.0


@pytest.mark.slow  # 39 s; the bit-exact C/Python tests stay in the fast suite
def test_shipped_float_module_tracks_continuous_reference_on_replayed_closed_loop_inputs(shipped):
    """Float module vs the synthesis package's exact continuous-time controller (RK4, fine delay
    history), on inputs recorded from a closed loop with a delayed patient: target steps, sensor
    noise, and rho sweeping inside and outside the design box. With the design's prefilter the
    feedback controller's input is the module's reference r_m and its output the command minus the
    feedforward (the prefilter itself is checked in tests/codegen/test_reference_prefilter.py)."""
    import random

    mod, design = shipped["mod"], shipped["design"]
    rng = random.Random(11)
    ctrl = mod.Controller()
    seq, got = [], []
    two_dof = mod.REFERENCE_ENABLED
    dmap, hist = 0.0, [0.0] * 1000
    for k in range(3000):  # 300 s at 0.1 s
        t = 0.1 * k
        rho = (0.6 + 0.5 * math.sin(t / 40.0), 150.0 + 70.0 * math.sin(t / 30.0), 30.0)
        target = 75.0 if k < 1500 else 70.0
        sample = (60.0 + dmap + rng.gauss(0.0, 0.5), target, *rho)
        u = ctrl.step(*sample)
        u_ff = ctrl.reference()[2] if two_dof else 0.0
        # The tolerance below assumes the linear region; the one exception is the design's first
        # seconds, where the continuous u dips a hair below 0 ml/h and the module clamps it. With
        # the prefilter the total command reaches 0 ml/h (a real pump limit) after the target
        # falls: the comparison stops there.
        if ctrl.status.saturated and two_dof:
            break
        assert not ctrl.status.saturated or u == 0.0
        seq.append((sample[0], ctrl.reference()[1], *rho) if two_dof else sample)
        got.append(u - u_ff)
        hist[k % 1000] = u
        ud = hist[(k - 300) % 1000] if k >= 300 else 0.0  # 30 s patient delay
        a = math.exp(-0.1 / 150.0)
        dmap = a * dmap + 0.55 * (1 - a) * ud
    ref = continuous_reference(
        seq,
        controller_fn=design.controller_fn,
        box=design.box,
        rates=design.rate_bounds,
        omega=design.omega,
        lambda_=design.lambda_,
    )
    clip = -math.inf if two_dof else 0.0  # the feedback share may be negative with a feedforward
    assert len(got) >= 2000  # >= 200 s of the linear region compared
    err = max(abs(a - max(b, clip)) for a, b in zip(got, ref, strict=True))
    bound = mod.FLOAT_VS_CONTINUOUS_TOL_ML_H + mod.OFFGRID_REL_BOUND * max(np.abs(ref))
    assert err <= bound, (err, bound)
    assert max(np.abs(ref)) > (2.0 if two_dof else 10.0)  # the feedback did work
    assert two_dof or min(ref) > -bound  # the clamped dip is within the tolerance too
