"""Shared parts of the codegen tests: a hand-built scheduled delayed controller, its design, the
emitted targets (Python modules, C libraries) and independent references to compare them with.

The controller is built by hand (a PI-like feedthrough scaled by 0.55/K plus three scheduled states
with a delayed coupling), so the tests that use it need no synthesis artifact.
"""

from __future__ import annotations

import ctypes
import importlib.util
import math
import random
import shutil
import subprocess
from pathlib import Path

import numpy as np

from pressor.codegen import pipeline as pl
from pressor.codegen.discretise import DelayedControllerMatrices, composite_continuous
from pressor.codegen.tables import TabulationProof

BOX = np.array([[0.25, 1.0], [100.0, 200.0], [10.0, 45.0]])
RATES = np.array([2e-4, 0.06, 0.1])
TS = 0.1
#: The hand-built controller's fixed 17x3x3 table meets this bound (the shipped pipeline enforces
#: the tighter pl.OFFGRID_REL_TOL by refining its own grid).
HAND_GRID_REL_TOL = 0.02


def example_controller(rho) -> DelayedControllerMatrices:
    """A stable-in-loop scheduled delayed controller (time in s, y = [e, x_e])."""
    K, T, tau = (float(r) for r in rho)
    g = 0.55 / K
    return DelayedControllerMatrices(
        Ak=np.array([[-1.0 / T, 0, 0], [0, -0.05, 0], [0, 0, -0.2]]),
        Adk=np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.002 * tau / 40, 0]]),
        Bk=np.array([[1.0, 0], [0, 0], [0, 0.001]]),
        Ck=np.array([[0.005 * g, -0.01, 0.02]]),
        Cdk=np.array([[0, 0.01 * T / 150, 0]]),
        Dk=np.array([[3.0 * g, 0.017 * g]]),
    )


def hand_design() -> pl.LoadedDesign:
    """The hand-built controller as a design over BOX with RATES (no artifact)."""
    return pl.LoadedDesign(
        sha256="0" * 64,
        display_path="example.npz",
        controller_fn=example_controller,
        box=BOX,
        rate_bounds=RATES,
        omega=0.1,
        lambda_=0.1,
        max_rate_ml_h=120.0,
        synthesis_counts=(3, 3, 3),
    )


def load_module(path: Path):
    spec = importlib.util.spec_from_file_location(f"gen_{abs(hash(str(path))):x}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def emit_targets(design: pl.LoadedDesign, proof: TabulationProof, root: Path) -> dict:
    """q31/q15 plans, the Python module (loaded, and its source) and the C libraries (int and
    float) of ``design`` under ``root``; the C ones only where gcc is installed."""
    out: dict = {}
    gcc = shutil.which("gcc")
    for fmt in ("q31", "q15"):
        plan = pl.quantise(design, proof, fmt)
        out[f"plan_{fmt}"] = plan
        d = root / fmt
        d.mkdir()
        src = pl.emit(design, proof, plan, "python").files["lpv_map_controller.py"]
        (d / "lpv_map_controller.py").write_text(src)
        out[f"py_{fmt}"] = load_module(d / "lpv_map_controller.py")
        out[f"src_{fmt}"] = src
        for flt in (False, True):
            files = pl.emit(design, proof, plan, "c", c_float=flt).files
            cd = d / ("cf" if flt else "c")
            cd.mkdir()
            for name, text in files.items():
                (cd / name).write_text(text)
            if gcc:
                lib = cd / "libctl.so"
                subprocess.run(
                    [gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2",
                     "-shared", "-fPIC", "-o", str(lib), str(cd / "lpv_map_controller.c")],
                    check=True, capture_output=True, text=True,
                )  # fmt: skip
                out[f"c_{fmt}{'_f' if flt else ''}"] = lib
    return out


class CController:
    """ctypes wrapper of the generated C step with a caller-owned state buffer."""

    def __init__(self, lib_path: Path) -> None:
        lib = ctypes.CDLL(str(lib_path))
        lib.lpvmap_step.restype = ctypes.c_double
        lib.lpvmap_step.argtypes = [ctypes.c_void_p] + [ctypes.c_double] * 5
        lib.lpvmap_state_size.restype = ctypes.c_uint32
        self.lib = lib
        self.state = ctypes.create_string_buffer(lib.lpvmap_state_size())
        lib.lpvmap_reset(self.state)

    def step(self, *args: float) -> float:
        return self.lib.lpvmap_step(self.state, *args)


def random_inputs(seed: int, n: int):
    """Closed-loop-like input sequences: MAP with steps and noise, rho sweeping in and out of the box,
    occasional NaN samples."""
    rng = random.Random(seed)
    seq = []
    for k in range(n):
        target = 90.0 if (k // 3000) % 2 == 0 else 110.0
        mp = 80.0 + 15.0 * math.sin(k / 700.0) + rng.gauss(0.0, 2.0)
        if rng.random() < 0.002:
            mp = float("nan")
        K = 0.6 + 0.6 * math.sin(k / 900.0) + (rng.random() < 0.01) * rng.uniform(-2, 2)
        T = 150.0 + 80.0 * math.sin(k / 1300.0)
        tau = 27.0 + 25.0 * math.sin(k / 500.0)
        seq.append((mp, target, K, T, tau))
    return seq


def fopdt_closed_loop(ctrl, duration_s: float, seed: int, rho_fn=None):
    """Closed loop with a K/(T s + 1) e^(-tau s) patient (baseline 70 mmHg), sensor noise 1 mmHg,
    target steps; returns the command sequence (ml/h)."""
    rng = random.Random(seed)
    n = int(round(duration_s / TS))
    hist = [0.0] * 1000
    dmap = 0.0
    cmds = []
    for k in range(n):
        t = k * TS
        K, T, tau = rho_fn(t) if rho_fn else (0.5, 140.0, 30.0)
        target = 90.0 if t < duration_s / 2 else 80.0
        u = ctrl.step(70.0 + dmap + rng.gauss(0.0, 1.0), target, K, T, tau)
        cmds.append(u)
        hist[k % 1000] = u
        d = tau / TS
        nd = int(d)
        f = d - nd
        ud = (1 - f) * hist[(k - nd) % 1000] + f * hist[(k - nd - 1) % 1000] if k >= nd + 1 else 0.0
        a = math.exp(-TS / T)
        dmap = a * dmap + K * (1 - a) * ud
    return cmds


def continuous_reference(
    seq,
    substeps: int = 20,
    controller_fn=example_controller,
    box=BOX,
    rates=RATES,
    omega: float = 0.1,
    lambda_: float = 0.1,
):
    """RK4 on the exact continuous controller (composite [x_k, u, x_e], any controller order n_k);
    rho clamped and rate-limited as specified; x_k(t - tau) read from a fine history; u returned at
    the end of each sample."""
    BOX, RATES = np.asarray(box, float), np.asarray(rates, float)  # noqa: N806
    lo, hi = BOX[:, 0], BOX[:, 1]
    h = TS / substeps
    nk = np.atleast_2d(np.asarray(controller_fn(lo).Ak)).shape[0]
    z = np.zeros(nk + 2)
    hist_t, hist_x = [0.0], [np.zeros(nk)]
    prev = None
    out = []
    for k, (mp, target, *rho) in enumerate(seq):
        r = np.clip(np.asarray(rho, float), lo, hi)
        if prev is not None:
            r = np.clip(r, prev - RATES * TS, prev + RATES * TS)
        prev = r
        Ac, Bc = composite_continuous(controller_fn(r), omega, lambda_)
        e = target - mp
        ht, hx = np.asarray(hist_t), np.asarray(hist_x)

        def xd_at(t, r=r, ht=ht, hx=hx):
            tq = t - r[2]
            if tq <= 0.0:
                return np.zeros(nk)
            return np.array([np.interp(tq, ht, hx[:, i]) for i in range(nk)])

        t0 = k * TS
        for s in range(substeps):
            t = t0 + s * h

            def f(tt, zz, Ac=Ac, Bc=Bc, e=e, xd_at=xd_at):
                return Ac @ zz + Bc @ np.concatenate([xd_at(tt), [e]])

            k1 = f(t, z)
            k2 = f(t + h / 2, z + h / 2 * k1)
            k3 = f(t + h / 2, z + h / 2 * k2)
            k4 = f(t + h, z + h * k3)
            z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            hist_t.append(t + h)
            hist_x.append(z[:nk].copy())
        out.append(z[nk])
    return out
