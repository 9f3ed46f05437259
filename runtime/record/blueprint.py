"""The layout the rerun viewer opens a recording on (docs/VIEWER.md describes every panel).

The viewer opens on the ``sim_time`` timeline (a duration: the axis reads in minutes and seconds)
and every plot shows the WHOLE run (both ends of its visible time range infinite), whatever the
time cursor, so a 51 → 71 mmHg rise is visible at once. A legend stays only where it fits clear of
the traces (:data:`LEGENDS`): the MAP's and the dose's in their bottom-right corners (once the MAP
has risen it sits at the target, at the top of its axis, and the maintenance dose near the top
of its) and the safety state's top right; every other plot names its series' colours in its title
instead, since a legend there covered half of a small panel (issue 40). The infusion row is as tall as the MAP's, so its y axis has several labelled ticks and the
maintenance rate reads off it; the safety state's y axis spans every state code (0-6), so the
trace sits below the legend. Series colours are set where the recorder logs each channel's static
style (:data:`SERIES_COLORS`), so the commanded and the delivered infusion never share one.

Entity paths referenced here but absent from a recording (``/patient/map_true_mmhg`` when the
runtime never saw the true MAP, ``/schedule/estimated/*`` when no estimator ran) leave their view
without that series; referencing them is harmless.
"""

from __future__ import annotations

import rerun.blueprint as rrb
import rerun.encodings as rre

#: the timeline the viewer opens on (s of simulated time, logged as a duration)
TIMELINE = "sim_time"
#: the safety event log (supervisor transitions, advisory faults) and the run's event markers
EVENTS_ENTITY = "/safety/events"
MARKERS_LOG = "/events/log"
DISTURBANCE_MARKERS = "/events/disturbance"
FAULT_MARKERS = "/events/fault"
TRANSITION_MARKERS = "/safety/transitions"
#: scheduling variables: (name, unit, device entity, entity as the controller used it)
SCHED_VARS: tuple[tuple[str, str, str, str], ...] = (
    ("K", "mmHg/(ml/h)", "/schedule/K", "/controller/rho/K"),
    ("T", "s", "/schedule/T_s", "/controller/rho/T_s"),
    ("tau", "s", "/schedule/tau_s", "/controller/rho/tau_s"),
)
#: design-box bounds: entity of the (low, high) of each scheduling variable, K, T, τ order
BOX_ENTITIES: tuple[tuple[str, str], ...] = tuple(
    (f"/schedule/box/{name}_lo", f"/schedule/box/{name}_hi") for name, *_ in SCHED_VARS
)

_BLUE, _ORANGE, _GREEN, _RED = (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40)
_PURPLE, _GREY, _BROWN, _BLACK = (148, 103, 189), (127, 127, 127), (140, 86, 75), (0, 0, 0)
_LIGHT_GREEN = (152, 223, 138)
#: entity -> RGB colour of its series (the recorder logs it with the static series style)
SERIES_COLORS: dict[str, tuple[int, int, int]] = {
    "/patient/map_mmhg": _BLUE,
    "/patient/map_true_mmhg": _PURPLE,
    "/controller/target_mmhg": _BLACK,
    "/controller/command_ml_h": _ORANGE,
    "/pump/command_ml_h": _BROWN,
    "/pump/rate_ml_h": _GREEN,
    "/pump/volume_ml": _GREEN,
    "/dose/delivered_ug_min": _GREEN,
    "/dose/delivered_ug_kg_min": _PURPLE,
    "/schedule/K": _BLUE,
    "/schedule/T_s": _BLUE,
    "/schedule/tau_s": _BLUE,
    "/controller/rho/K": _ORANGE,
    "/controller/rho/T_s": _ORANGE,
    "/controller/rho/tau_s": _ORANGE,
    **{f"/schedule/estimated/{n}": _GREEN for n in ("K", "T_s", "tau_s")},
    **{
        f"/schedule/estimated/{n}": _LIGHT_GREEN
        for n in ("K_lo", "K_hi", "T_lo_s", "T_hi_s", "tau_lo_s", "tau_hi_s")
    },
    "/loop/exec_us": _BLUE,
    "/loop/lateness_us": _ORANGE,
    "/safety/state": _BLUE,
    "/safety/alarm": _RED,
    "/safety/faults": _PURPLE,
    "/link/bad_frames": _BROWN,
    DISTURBANCE_MARKERS: _PURPLE,
    FAULT_MARKERS: _RED,
    TRANSITION_MARKERS: _RED,
}
BOX_COLOR = _GREY

_WHOLE_RUN = rrb.VisibleTimeRange(
    TIMELINE, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
)

# the data range alone is not enough: without a view range of its own the viewer's x axis follows
# the time cursor (about 100 s around the newest tick when a recording streams in)
_WHOLE_RUN_AXIS = rrb.archetypes.TimeAxis(
    view_range=rre.TimeRange(
        start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
    )
)


#: where a plot keeps its legend: view name prefix -> corner (the other plots hide theirs)
LEGENDS: dict[str, rrb.Corner2D] = {
    "MAP vs target": rrb.Corner2D.RightBottom,
    "Dose": rrb.Corner2D.RightBottom,
    "Safety state": rrb.Corner2D.RightTop,
}
#: the safety state's y axis: every supervisor state code (0 STARTUP ... 6 MANUAL), half a step
#: of margin, so AUTO (1) and the alarm (0/1) sit at the bottom, clear of the legend
SAFETY_STATE_AXIS = (-0.5, 6.5)
#: the rows' heights, top to bottom: MAP; infusion, dose, volume; K, T, tau; timing and safety
ROW_SHARES = (3.0, 3.0, 2.0, 2.0)


def _plot(
    name: str, contents: list[str], axis_y: rrb.archetypes.ScalarAxis | None = None
) -> rrb.TimeSeriesView:
    """A time-series view of ``contents`` over the whole run, its legend where :data:`LEGENDS`
    puts it, else hidden (the title names the colours)."""
    corner = next((c for prefix, c in LEGENDS.items() if name.startswith(prefix)), None)
    return rrb.TimeSeriesView(
        name=name,
        origin="/",
        contents=contents,
        time_ranges=_WHOLE_RUN,
        axis_x=_WHOLE_RUN_AXIS,
        axis_y=axis_y,
        plot_legend=rrb.PlotLegend(corner=corner, visible=corner is not None),
    )


def _sched_view(index: int) -> rrb.TimeSeriesView:
    """K, T or τ: the device's, the controller's (clamped, rate-limited), an estimator's with its
    90 % band (``/schedule/estimated/*``, when one ran) and the design box."""
    name, unit, device, used = SCHED_VARS[index]
    suffix = "" if name == "K" else "_s"
    estimated = [f"/schedule/estimated/{name}{s}" for s in (suffix, "_lo" + suffix, "_hi" + suffix)]
    return _plot(
        f"{name} ({unit}): device blue, used orange, estimate green, box grey",
        [device, used, *estimated, *BOX_ENTITIES[index]],
    )


#: the dose channels of a ``pressor run`` recording (:func:`pressor.runtime.inputs.dosing.log_dose_series`)
DOSE_ENTITIES = (
    "/dose/command_ug_min",
    "/dose/command_ug_kg_min",
    "/dose/hard_max",
    "/dose/soft_max",
)


#: the delivered dose of a ``pressor sil`` recording (the simulated pump's delivered rate in the
#: syringe's µg/min and, per the patient's weight or the 70 kg reference, µg/kg/min)
DELIVERED_DOSE_ENTITIES = ("/dose/delivered_ug_min", "/dose/delivered_ug_kg_min")
#: the one the dose plot shows: µg/kg/min, the clinical unit (in µg/min on the same axis it was a
#: flat line at the bottom, about 70 times smaller)
DELIVERED_DOSE_PLOTTED = DELIVERED_DOSE_ENTITIES[1]


def default_blueprint(dose: bool = False) -> rrb.Blueprint:
    """The layout the viewer opens on: MAP, infusion in ml/h with the dose beside it, volume,
    scheduling, timing and safety. The dose plot holds, with ``dose`` (``pressor run``), the
    commanded dose (µg/min, µg/kg/min) and the drug library's hard and soft maxima, else
    (``pressor sil``) the dose the simulated pump delivered in µg/kg/min (its µg/min is recorded,
    not plotted)."""
    infusion = [
        _plot(
            "Infusion (ml/h): command orange, sent brown, delivered green",
            ["/controller/command_ml_h", "/pump/command_ml_h", "/pump/rate_ml_h"],
        )
    ]
    if dose:
        infusion.append(_plot("Dose (ug/min, ug/kg/min; library maxima)", list(DOSE_ENTITIES)))
    else:
        infusion.append(_plot("Dose delivered (ug/kg/min)", [DELIVERED_DOSE_PLOTTED]))
    infusion.append(_plot("Volume infused (ml)", ["/pump/volume_ml"]))
    return rrb.Blueprint(
        rrb.Vertical(
            _plot(
                "MAP vs target (mmHg)",
                [
                    "/patient/map_mmhg",
                    "/patient/map_true_mmhg",
                    "/controller/target_mmhg",
                    DISTURBANCE_MARKERS,
                    FAULT_MARKERS,
                ],
            ),
            rrb.Horizontal(*infusion, column_shares=[3, 2, 1]),
            rrb.Horizontal(*(_sched_view(i) for i in range(len(SCHED_VARS)))),
            rrb.Horizontal(
                _plot(
                    "Loop timing (us): execution blue, lateness orange",
                    ["/loop/exec_us", "/loop/lateness_us"],
                ),
                _plot(
                    "Safety state (0 STARTUP 1 AUTO 2 HOLD 3 FAILSAFE 4 RECOVERING 5 STOPPED 6 MANUAL)",
                    ["/safety/state", "/safety/alarm", TRANSITION_MARKERS],
                    axis_y=rrb.ScalarAxis(range=SAFETY_STATE_AXIS, zoom_lock=False),
                ),
                rrb.TextLogView(
                    name="Safety and run events", origin="/", contents=[EVENTS_ENTITY, MARKERS_LOG]
                ),
            ),
            row_shares=list(ROW_SHARES),
        ),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        collapse_panels=True,
    )
