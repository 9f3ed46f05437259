"""What ``pressor faults`` prints for the runtime supervisor: each fault kind with its detection
rule and bound under a :class:`pressor.runtime.core.supervisor_config.SupervisorConfig`, and the
reaction."""

from __future__ import annotations

from pressor.runtime.core.flatline import stuck_samples
from pressor.runtime.core.supervisor_config import SupervisorConfig


def detection_bounds(cfg: SupervisorConfig) -> list[tuple[str, str]]:
    """Each detectable fault kind with its detection rule and bound under ``cfg`` (for ``pressor faults``)."""
    ts = cfg.sample_period_s
    box = (
        "not checked (controller not scheduled)"
        if cfg.sched_box is None
        else f"K, T, tau outside {cfg.sched_box}; same tick"
    )
    rates = (
        "not checked"
        if cfg.sched_rate_bounds is None
        else f"|drho/dt| > {cfg.sched_rate_tolerance} x {cfg.sched_rate_bounds}; same tick"
    )
    return [
        ("MAP_NAN", f"non-finite MAP sample; same tick ({ts} s)"),
        (
            "MAP_RANGE",
            f"MAP outside [{cfg.map_min_mmhg}, {cfg.map_max_mmhg}] mmHg (line disconnect, flush);"
            " same tick",
        ),
        ("MAP_SPIKE", f"|MAP step| > {cfg.spike_mmhg} mmHg between samples; same tick"),
        (
            "MAP_FLATLINE",
            "new samples stuck within +/-max("
            f"{cfg.flatline_eps_mmhg} mmHg, quantum/2) for n samples and {cfg.flatline_s} s at"
            " least (n sized for a 1e-9 false alarm: "
            f"{stuck_samples(1.0, 1.0, cfg.flatline_eps_mmhg):.0f} at noise 1 mmHg, quantum 1"
            " mmHg), or their mean squared step below"
            f" 2 x ({cfg.flatline_ratio} x noise)^2 over {cfg.flatline_window} samples and"
            f" {cfg.flatline_s} s (noise >= quantum); only when the device announces noise > 0",
        ),
        ("SENSOR_QUALITY", "monitor flags the sample (quality bits but HELD); same tick"),
        (
            "STALE_SAMPLE",
            f"sample older than {cfg.stale_after_s} s (a HELD repeat ages from the last new one)",
        ),
        ("LINK_LOSS", f"no frame for {cfg.link_loss_after_s} s -> FAILSAFE at once"),
        ("SCHED_INVALID", "scheduling marked invalid or non-finite; same tick"),
        ("SCHED_OUT_OF_BOX", box),
        ("SCHED_RATE", rates),
        (
            "sched action",
            "SCHED_OUT_OF_BOX / SCHED_RATE "
            + (
                "advisory: flagged and logged, the controller clamps/rate-limits itself"
                if cfg.sched_action == "advise"
                else "hold like any other fault"
            ),
        ),
        ("TARGET_INVALID", "target non-finite or outside the MAP range; same tick"),
        ("COMMAND_INVALID", "controller returned a non-finite command; same tick, held"),
        (
            "CONTROLLER_FAULT",
            "pressor run: the controller raised or returned a non-number; same tick, held"
            " (sil, trial: the run ends, exit 1); under pressor run it and COMMAND_INVALID hold"
            " until the clinician's ack",
        ),
        ("COMMAND_CLAMPED", f"controller command outside [0, {cfg.max_rate_ml_h}] ml/h; clamped"),
        (
            "LINK_ERRORS",
            "bad CRC / junk / sequence gap / incomplete tick / refused signature since the last"
            " tick; same tick; advisory (bad frames are discarded, lost ticks resent)",
        ),
        (
            "PUMP_ALARM",
            "pump status reports occlusion, empty reservoir or pump watchdog; the tick the status"
            " arrives (1 tick after the cause); the held command stays the runtime's own",
        ),
        (
            "PUMP_MISMATCH",
            f"|delivered - command| > max({cfg.pump_mismatch_abs_ml_h} ml/h,"
            f" {cfg.pump_mismatch_rel:g} x command) for {cfg.pump_mismatch_s} s; at once for a"
            " delivered rate no pump gives (infinite, negative, above the pump's maximum)",
        ),
        (
            "SAMPLE_TIME",
            "the sample's sim_time_s not finite, earlier than the previous one, or not tick x"
            f" {ts} s within half a period; same tick, the sample not used",
        ),
        (
            "RECORD_ERROR",
            "a writer of the record (.tlog, .rrd) failed (full disk, I/O error); the record"
            " stops, control goes on; advisory alarm for the rest of the run",
        ),
        (
            "DEVICE_CHANGED",
            "a device hello in the middle of the run changes drug, concentration, pump maximum,"
            " noise, sample period or link mode: refused on the wire (the run keeps the first"
            " hello), held until the clinician's ack",
        ),
        (
            "ESTIMATOR_FALLBACK",
            "--schedule estimated: the estimator's health check rejected its estimate (diverged,"
            " non-finite, K or T implausible); scheduling falls back to the prior (nominal"
            " patient), the loop keeps running; advisory, alarm; same tick",
        ),
        (
            "ESTIMATE_OUT_OF_BOX",
            "--schedule estimated: the estimate outside the design box for"
            f" {cfg.estimate_box_s:g} s; advisory alarm (the controller clamps)"
            + ("" if cfg.sched_box is not None else "; not checked (controller not scheduled)"),
        ),
        (
            "DOSE_*",
            "pressor run, drug library (docs/DRUGS.md): final command cut to the hard (HARD) or"
            " hourly (HOUR) dose maximum, or above the soft one (SOFT); advisory alarm; same tick",
        ),
        (
            "reaction",
            f"HOLD last command (alarm); FAILSAFE after {cfg.hold_max_s} s, ramping"
            f" {cfg.failsafe_ramp_ml_h_per_s} ml/h/s to "
            + ("the held rate" if cfg.safe_rate_ml_h is None else f"{cfg.safe_rate_ml_h} ml/h"),
        ),
        (
            "re-entry",
            f"inputs good for {cfg.recover_after_s} s -> RECOVERING, command slews"
            f" <= {cfg.reentry_step_ml_h} ml/h per tick to the controller's, then AUTO",
        ),
    ]
