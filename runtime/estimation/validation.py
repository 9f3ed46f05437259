"""Model validation for the scheduling source: which fixed FOPDT model predicts the measured MAP?

A bank of fixed first-order-plus-delay models, a grid over the design box plus the nominal one,
each *simulated* from the delivered rate alone (nothing fitted, so every window is held-out data
for every model) and scored on how well it predicts the *change* of the MAP over a horizon::

    x_m,j = a_m·x_m,j−1 + b_m·ū_{j−d_m},        a_m = e^(−Δ/T_m), b_m = K_m·(1 − a_m)
    e_m,j = (ȳ_j − ȳ_{j−H}) − (x_m,j − x_m,j−H)
    S_m   = λ·S_m + e_m,j²                     λ = e^(−Δ/memory)

with ȳ, ū the estimator's window means (Δ = its window, 2 s) and H the horizon (default 60 s).
The difference over H removes the baseline (unknown, shifting) and all but H/(time scale) of
any slow drift the FOPDT class lacks: a haemorrhage's ramp, a peripheral compartment filling over
hours, tolerance creeping the gain down; none of it is read as K, T or τ.

The source adopts a model only while it predicts the MAP changes better than the nominal model by
a margin that is both relative (``margin_rel``: S below (1 − margin_rel)·S_nominal) and
statistical (S_nominal − S ≥ ``margin_sigma2`` times the variance of a difference of two window
means, 2σ², σ² the monitor noise of a window mean the estimator reads from the data); among the
models within ``near_sigma2``·2σ² of the best it takes the lowest-gain one (largest K, then
smallest T: the smallest feedforward). An adopted model is kept until another one beats it by the
same margins, and dropped for the nominal model when it no longer beats the nominal one by half
of them. Cost: one multiply-add and one squared error per model and window, staggered over the
window's ticks.
"""

from __future__ import annotations

import math

from pressor.contracts.checks import check_range

#: default grid of the bank over the design box: K (mmHg/(ml/h)), T (s), τ (s)
K_GRID = (0.25, 0.35, 0.45, 0.55, 0.7, 0.85, 1.0)
T_GRID_S = (100.0, 150.0, 200.0)
TAU_GRID_S = (15.0, 30.0, 45.0)


class ModelBank:
    """Fixed FOPDT models scored on held-out MAP changes (module docstring).

    Parameters
    ----------
    window_s
        The window (s) of the means fed to :meth:`close_window`, > 0.
    ticks_per_window
        Ticks per window (the bank's updates are spread over them), >= 1.
    nominal
        The nominal model (K mmHg/(ml/h), T s, τ s), model 0 of the bank.
    K_grid, T_grid_s, tau_grid_s
        The grid of the other models (mmHg/(ml/h), s, s); every value > 0 (τ >= 0).
    horizon_s
        The prediction horizon H (s), at least one window.
    memory_s
        Memory of the scores (s), > window_s.
    margin_rel
        Relative margin in (0, 1) a model's score must beat the nominal's (and the adopted one's) by.
    margin_sigma2
        Statistical margin, in variances of a difference of two window means, > 0.
    near_sigma2
        Models within this many such variances of the best count as equally good, >= 0.
    """

    def __init__(
        self,
        window_s: float,
        ticks_per_window: int,
        nominal: tuple[float, float, float],
        K_grid: tuple[float, ...] = K_GRID,
        T_grid_s: tuple[float, ...] = T_GRID_S,
        tau_grid_s: tuple[float, ...] = TAU_GRID_S,
        horizon_s: float = 60.0,
        memory_s: float = 600.0,
        margin_rel: float = 0.25,
        margin_sigma2: float = 20.0,
        near_sigma2: float = 1.0,
    ) -> None:
        check_range("window_s", window_s, 0.0, lo_open=True, unit="s")
        if not (isinstance(ticks_per_window, int) and ticks_per_window >= 1):
            raise ValueError(f"ticks_per_window={ticks_per_window!r} must be an integer >= 1")
        check_range("horizon_s", horizon_s, window_s, unit="s")
        check_range("memory_s", memory_s, window_s, lo_open=True, unit="s")
        check_range("margin_rel", margin_rel, 0.0, 1.0, lo_open=True, hi_open=True)
        check_range("margin_sigma2", margin_sigma2, 0.0, lo_open=True)
        check_range("near_sigma2", near_sigma2, 0.0)
        if len(nominal) != 3:
            raise ValueError(f"nominal={nominal!r} must be (K, T_s, tau_s)")
        for name, grid in (("K", (nominal[0], *K_grid)), ("T_s", (nominal[1], *T_grid_s))):
            for v in grid:
                check_range(f"{name} of the bank", v, 0.0, lo_open=True)
        for v in (nominal[2], *tau_grid_s):
            check_range("tau_s of the bank", v, 0.0, unit="s")
        models = [tuple(float(v) for v in nominal)]
        models += [(k, t, d) for k in K_grid for t in T_grid_s for d in tau_grid_s]
        self.models: tuple[tuple[float, float, float], ...] = tuple(models)  # type: ignore[assignment]
        n = len(self.models)
        self._a = [math.exp(-window_s / t) for _, t, _ in self.models]
        self._b = [k * (1.0 - a) for (k, _, _), a in zip(self.models, self._a, strict=True)]
        self._d = [max(1, round(d / window_s)) for _, _, d in self.models]
        self._h = max(1, round(horizon_s / window_s))
        self._u = [0.0] * (max(self._d) + 1)  # ring of window rates (ml/h)
        self._y = [math.nan] * (self._h + 1)  # ring of window means (mmHg)
        self._x = [[0.0] * (self._h + 1) for _ in range(n)]  # rings of simulated responses
        self.score = [0.0] * n
        self._forget = math.exp(-window_s / memory_s)
        self._rel, self._sig, self._near = margin_rel, margin_sigma2, near_sigma2
        self._per_tick = -(-n // ticks_per_window)
        self._j = -1
        self._next = n
        self._dy = math.nan
        self._var2 = math.nan
        self.adopted = 0  # index of the adopted model (0: the nominal one)

    @property
    def target(self) -> tuple[float, float, float]:
        """The adopted model's (K mmHg/(ml/h), T s, τ s)."""
        return self.models[self.adopted]

    def close_window(self, y_mmhg: float, u_ml_h: float, noise_var_mmhg2: float) -> None:
        """Take a closed window: its mean MAP (mmHg, NaN when too few samples), mean delivered
        rate (ml/h, NaN when unknown: taken as 0) and the monitor noise variance of a window mean
        (mmHg²). The models are updated over the next ticks (:meth:`step`)."""
        self._j += 1
        j = self._j
        self._u[j % len(self._u)] = u_ml_h if u_ml_h == u_ml_h else 0.0
        h1 = self._h + 1
        self._y[j % h1] = y_mmhg
        self._dy = y_mmhg - self._y[(j - self._h) % h1] if j >= self._h else math.nan
        self._var2 = 2.0 * noise_var_mmhg2
        self._next = 0

    def step(self) -> None:
        """Update the next few models of the pending window; decide after the last one."""
        n = len(self.models)
        if self._next >= n:
            return
        stop = min(n, self._next + self._per_tick)
        j, h1, ring, nu = self._j, self._h + 1, self._u, len(self._u)
        dy, f = self._dy, self._forget
        a, b, d, xs, score = self._a, self._b, self._d, self._x, self.score
        slot, old = j % h1, (j - self._h) % h1
        for m in range(self._next, stop):
            xm = xs[m]
            x = a[m] * xm[(j - 1) % h1] + b[m] * ring[(j - d[m]) % nu]
            xm[slot] = x
            if dy == dy:
                e = dy - (x - xm[old])
                score[m] = f * score[m] + e * e
        self._next = stop
        if stop == n and dy == dy:
            self._decide()

    def _beats(self, s: float, ref: float, scale: float) -> bool:
        return s < (1.0 - self._rel * scale) * ref and ref - s >= scale * self._sig * self._var2

    def _decide(self) -> None:
        score, models = self.score, self.models
        n = len(models)
        best_s = min(score)
        tol = best_s + self._near * self._var2
        pick = min((m for m in range(n) if score[m] <= tol), key=lambda m: (-models[m][0],
                   models[m][1], score[m]))  # fmt: skip
        cur = self.adopted
        if cur and not self._beats(score[cur], score[0], 0.5):
            cur = 0  # no longer better than the nominal model
        if pick != cur and self._beats(score[pick], score[0], 1.0):
            if cur == 0 or self._beats(score[pick], score[cur], 1.0):
                cur = pick
        self.adopted = cur
