"""The recording's per-tick channels: entity paths, legend labels, column order.

:data:`CHANNELS` is the column order of :meth:`pressor.runtime.record.recorder.Recorder.record`;
:func:`record_schedule` fills a row's ``/schedule/estimated/*`` columns from a tick's schedule.
"""

from __future__ import annotations

import math

from pressor.runtime.core.closed_loop import TickRecord

#: (entity path, legend label) — the column order of :meth:`Recorder.record`.
CHANNELS: tuple[tuple[str, str], ...] = (
    ("/patient/map_mmhg", "MAP measured (mmHg)"),
    ("/controller/target_mmhg", "target (mmHg)"),
    ("/controller/command_ml_h", "controller command (ml/h)"),
    ("/pump/command_ml_h", "command sent (ml/h)"),
    ("/pump/rate_ml_h", "delivered rate (ml/h)"),
    ("/pump/volume_ml", "volume delivered (ml)"),
    ("/schedule/K", "K (mmHg/(ml/h))"),
    ("/schedule/T_s", "T (s)"),
    ("/schedule/tau_s", "tau (s)"),
    ("/controller/rho/K", "K as the controller used it (mmHg/(ml/h))"),
    ("/controller/rho/T_s", "T as the controller used it (s)"),
    ("/controller/rho/tau_s", "tau as the controller used it (s)"),
    ("/loop/exec_us", "execution time (us)"),
    ("/loop/lateness_us", "release lateness (us)"),
    (
        "/safety/state",
        "supervisor state (0 STARTUP 1 AUTO 2 HOLD 3 FAILSAFE 4 RECOVERING 5 STOPPED 6 MANUAL)",
    ),
    ("/safety/faults", "fault bits"),
    ("/safety/alarm", "alarm (0/1)"),
    ("/link/bad_frames", "bad frames (count)"),
    ("/schedule/estimated/K", "K scheduled on (mmHg/(ml/h))"),
    ("/schedule/estimated/T_s", "T scheduled on (s)"),
    ("/schedule/estimated/tau_s", "tau scheduled on (s)"),
    ("/schedule/estimated/K_lo", "K 90 % band low (mmHg/(ml/h))"),
    ("/schedule/estimated/K_hi", "K 90 % band high (mmHg/(ml/h))"),
    ("/schedule/estimated/T_lo_s", "T 90 % band low (s)"),
    ("/schedule/estimated/T_hi_s", "T 90 % band high (s)"),
    ("/schedule/estimated/tau_lo_s", "tau 90 % interval low (s)"),
    ("/schedule/estimated/tau_hi_s", "tau 90 % interval high (s)"),
)
#: standard normal quantile of a two-sided 90 % band (K and T bands from their standard deviations)
_Z90 = 1.6449
CHANNEL_INDEX: dict[str, int] = {path: i for i, (path, _) in enumerate(CHANNELS)}
_BAND_CHANNELS = tuple(
    f"/schedule/estimated/{name}"
    for name in ("K_lo", "K_hi", "T_lo_s", "T_hi_s", "tau_lo_s", "tau_hi_s")
)


def record_schedule(rec: TickRecord, row: list[float]) -> None:
    """``/schedule/estimated/*``: the K, T, τ the controller was scheduled on when the source
    is not the oracle (``/schedule/K`` ... stay the device's values, its truth when it sends
    one), with the estimator's 90 % bands (NaN for the nominal source and the oracle)."""
    ix = CHANNEL_INDEX
    sched = rec.schedule
    nan = math.nan
    own = sched.source != "oracle"
    row[ix["/schedule/estimated/K"]] = sched.K if own else nan
    row[ix["/schedule/estimated/T_s"]] = sched.T_s if own else nan
    row[ix["/schedule/estimated/tau_s"]] = sched.tau_s if own else nan
    est = sched.estimate
    if est is None:
        band = (nan,) * 6
    else:
        dk, dt = _Z90 * est.K_std, _Z90 * est.T_std_s
        band = (est.K - dk, est.K + dk, est.T_s - dt, est.T_s + dt, est.tau_lo_s, est.tau_hi_s)
    for name, value in zip(_BAND_CHANNELS, band, strict=True):
        row[ix[name]] = value
