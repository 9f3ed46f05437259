"""The viewer's layout and annotations, read back from the .rrd of a real ``pressor sil`` run."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from rerun.chunk import RrdReader

from pressor.runtime.generated import lpv_map_controller as lpv
from pressor.runtime.record.blueprint import (
    BOX_ENTITIES,
    DISTURBANCE_MARKERS,
    FAULT_MARKERS,
    MARKERS_LOG,
    SERIES_COLORS,
    TIMELINE,
)
from tests.support.sil_helpers import pressor, rrd_columns

FAULT_AT_S = 30.0


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("bp")
    scenario = d / "dip.toml"  # a hemorrhage at 60 s inside a 120 s run
    scenario.write_text(
        'name = "dip"\nduration_s = 120.0\n[patient]\nmode = "nonlinear"\n'
        '[target]\nstep_mmhg = 20.0\n[[disturbances]]\nkind = "hemorrhage"\nstart_s = 60.0\n'
        "ramp_s = 30.0\ndepth_mmhg = 10.0\n"
    )
    proc = pressor(
        "sil",
        *("--controller", "lpv", "--schedule", "oracle"),  # the device's schedule, clamped
        *("--scenario", "dip.toml", "--fault", f"pump-occlusion:{FAULT_AT_S:g}"),
        *("--rrd", "run.rrd"),
        cwd=d,
    )
    assert proc.returncode in (0, 1), proc.stderr
    return d / "run.rrd"


def blueprint_rows(path: Path) -> dict[str, dict[str, Any]]:
    """Blueprint entity path -> {column: first value} (wall-clock timestamp columns left out)."""
    reader = RrdReader(str(path))
    (store,) = reader.blueprints()
    out: dict[str, dict[str, Any]] = {}
    for chunk in reader.stream(store=store).to_chunks():
        batch = chunk.to_record_batch()
        row = out.setdefault(str(chunk.entity_path), {})
        for name in batch.schema.names:
            col = batch.column(name)
            if "timestamp" not in str(col.type):
                row[name] = col[0]
    return out


def views(rows: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """View name -> {"kind", "contents", "ranges", "axis_range", "legend_corner",
    "legend_visible", "y_range"}."""
    out = {}
    for path, row in rows.items():
        if "ViewBlueprint:display_name" not in row:
            continue
        parts = {p.rsplit("/", 1)[1]: r for p, r in rows.items() if p.startswith(path + "/")}
        ranges = parts.get("VisibleTimeRanges", {}).get("VisibleTimeRanges:ranges")
        legend = parts.get("PlotLegend", {}).get("PlotLegend:corner")
        visible = parts.get("PlotLegend", {}).get("PlotLegend:visible")
        y_range = parts.get("ScalarAxis", {}).get("ScalarAxis:range")
        axis_range = parts.get("TimeAxis", {}).get("TimeAxis:view_range")
        out[row["ViewBlueprint:display_name"].as_py()[0]] = {
            "kind": row["ViewBlueprint:class_identifier"].as_py()[0],
            "contents": parts["ViewContents"]["ViewContents:query"].as_py(),
            "ranges": ranges,
            "axis_range": axis_range,
            "legend_corner": None if legend is None else legend.as_py()[0],
            "legend_visible": None if visible is None else visible.as_py()[0],
            "y_range": None if y_range is None else y_range.as_py()[0],
        }
    return out


def boundary_kinds(ends: Any) -> list[str]:
    """The variant names (``Infinite``, ``Absolute``, ...) of an array of time-range ends."""
    names = [ends.type[i].name for i in range(ends.type.num_fields)]
    return [names[ends.type.type_codes.index(c)] for c in ends.type_codes.to_pylist()]


def test_viewer_opens_on_the_sim_time_timeline(run):
    panel = blueprint_rows(run)["/time_panel"]
    assert panel["TimePanelBlueprint:timeline"].as_py() == [TIMELINE]


def view_named(v: dict[str, dict[str, Any]], prefix: str) -> dict[str, Any]:
    """The one view whose name starts with ``prefix`` (titles end with their colour keys)."""
    (name,) = [n for n in v if n.startswith(prefix)]
    return v[name]


def test_every_plot_shows_the_whole_run(run):
    plots = {n: v for n, v in views(blueprint_rows(run)).items() if v["kind"] == "TimeSeries"}
    assert len(plots) == 9  # the dose delivered beside the infusion (issue 40)
    for name, view in plots.items():
        ranges = view["ranges"].values  # one StructArray row per timeline
        assert ranges.field("timeline").to_pylist() == [TIMELINE], name
        assert boundary_kinds(ranges.field("range").field("start")) == ["Infinite"], name
        assert boundary_kinds(ranges.field("range").field("end")) == ["Infinite"], name
        # the x axis too: with only the data range set, the viewer's axis follows the time cursor
        axis = view["axis_range"].values
        assert boundary_kinds(axis.field("start")) == ["Infinite"], name
        assert boundary_kinds(axis.field("end")) == ["Infinite"], name


#: Corner2D codes as stored: LeftTop 1, RightTop 2, LeftBottom 3, RightBottom 4
RIGHT_TOP, RIGHT_BOTTOM = 2, 4


def test_legends_only_where_they_clear_the_traces_elsewhere_colours_in_the_title(run):
    v = views(blueprint_rows(run))
    plots = {n: p for n, p in v.items() if p["kind"] == "TimeSeries"}
    # the MAP sits at the target, the top of its axis, once risen; the dose near the top of its
    assert view_named(v, "MAP vs target")["legend_corner"] == RIGHT_BOTTOM
    assert view_named(v, "Dose delivered")["legend_corner"] == RIGHT_BOTTOM
    assert view_named(v, "Safety state")["legend_corner"] == RIGHT_TOP
    shown = {n for n, p in plots.items() if p["legend_visible"]}
    assert len(shown) == 3
    for name in set(plots) - shown:  # K, T, tau covered half their panel with 7 entries
        assert plots[name]["legend_visible"] is False, name
        assert plots[name]["legend_corner"] is None, name
        if len(plots[name]["contents"]) > 1:  # the title names the series' colours
            words = {w.strip(",") for w in name.split(":", 1)[1].split()}
            assert len(words & {"blue", "orange", "brown", "green", "grey"}) >= 2, name
    for var in ("K", "T", "tau"):
        title = next(n for n in plots if n.startswith(f"{var} ("))
        assert title.endswith("device blue, used orange, estimate green, box grey"), title


def test_infusion_row_is_as_tall_as_the_maps_and_safety_axis_spans_every_state(run):
    rows = blueprint_rows(run)
    shares = [
        r["ContainerBlueprint:row_shares"].as_py()
        for r in rows.values()
        if "ContainerBlueprint:row_shares" in r
    ]
    assert shares == [[3.0, 3.0, 2.0, 2.0]]  # was [3, 2, 2, 2]: one y tick on the infusion
    v = views(rows)
    assert view_named(v, "Safety state")["y_range"] == [-0.5, 6.5]  # 0 STARTUP ... 6 MANUAL
    for name, view in v.items():
        if not name.startswith("Safety state") and view["kind"] == "TimeSeries":
            assert view["y_range"] is None, name  # the others fit the whole run


def test_views_hold_map_infusion_volume_schedule_box_timing_and_safety(run):
    v = views(blueprint_rows(run))
    assert v["MAP vs target (mmHg)"]["contents"] == [
        "/patient/map_mmhg",
        "/patient/map_true_mmhg",
        "/controller/target_mmhg",
        DISTURBANCE_MARKERS,
        FAULT_MARKERS,
    ]
    assert view_named(v, "Infusion (ml/h)")["contents"] == [
        "/controller/command_ml_h",
        "/pump/command_ml_h",
        "/pump/rate_ml_h",
    ]
    assert v["Volume infused (ml)"]["contents"] == ["/pump/volume_ml"]
    k = view_named(v, "K (mmHg/(ml/h))")["contents"]
    assert k[:2] == ["/schedule/K", "/controller/rho/K"] and "/schedule/estimated/K" in k
    assert set(BOX_ENTITIES[0]) <= set(k)
    assert set(BOX_ENTITIES[2]) <= set(view_named(v, "tau (s)")["contents"])
    assert view_named(v, "Loop timing (us)")["contents"] == ["/loop/exec_us", "/loop/lateness_us"]
    assert "/safety/state" in v[next(n for n in v if n.startswith("Safety state"))]["contents"]
    assert v["Safety and run events"]["kind"] == "TextLog"


def test_commanded_and_delivered_infusion_have_distinct_colours(run):
    colours = {}
    for chunk in RrdReader(str(run)).stream().to_chunks():
        batch = chunk.to_record_batch()
        if "SeriesLines:colors" in batch.schema.names:
            colours[str(chunk.entity_path)] = batch.column("SeriesLines:colors")[0].as_py()
    cmd, rate = colours["/controller/command_ml_h"], colours["/pump/rate_ml_h"]
    assert cmd != rate
    r, g, b = SERIES_COLORS["/pump/rate_ml_h"]
    assert rate == [(r << 24) | (g << 16) | (b << 8) | 0xFF]


def test_design_box_spans_the_run_and_equals_the_loaded_modules_constants(run):
    cols = rrd_columns(run)
    last_tick = max(cols["/patient/map_mmhg"])
    for i, (lo_entity, hi_entity) in enumerate(BOX_ENTITIES):
        assert cols[lo_entity] == {0: lpv.GRID_LO[i], last_tick: lpv.GRID_LO[i]}
        assert cols[hi_entity] == {0: lpv.GRID_HI[i], last_tick: lpv.GRID_HI[i]}


def test_controller_schedule_is_the_device_schedule_clamped_to_the_box(run):
    cols = rrd_columns(run)
    for i, (used_entity, device_entity) in enumerate(
        (("/controller/rho/K", "/schedule/K"), ("/controller/rho/T_s", "/schedule/T_s"))
    ):
        used, device = cols[used_entity], cols[device_entity]
        stepped = sorted(t for t, v in used.items() if not math.isnan(v))
        assert len(stepped) > 0.5 * len(used)
        lo, hi = lpv.GRID_LO[i], lpv.GRID_HI[i]
        assert all(lo <= used[t] <= hi for t in stepped)
        first = stepped[0]  # the first step after reset: clamped, not rate-limited
        assert used[first] == pytest.approx(min(max(device[first], lo), hi))


def test_disturbance_and_fault_starts_are_marked_on_the_map_plot(run):
    cols = rrd_columns(run)
    (fault_tick,) = cols[FAULT_MARKERS]
    (dist_tick,) = cols[DISTURBANCE_MARKERS]
    assert fault_tick == round(FAULT_AT_S / 0.1) and dist_tick == 600
    assert cols[DISTURBANCE_MARKERS][dist_tick] == cols["/patient/map_mmhg"][dist_tick]
    texts = []
    for chunk in RrdReader(str(run)).stream().to_chunks():
        if str(chunk.entity_path) == MARKERS_LOG:
            batch = chunk.to_record_batch()
            if "TextLog:text" in batch.schema.names:
                texts += [v[0] for v in batch.column("TextLog:text").to_pylist()]
    assert texts == ["fault: pump-occlusion at 30 s", "disturbance: hemorrhage at 60 s"]


def test_smith_predictor_records_the_schedule_it_used_without_a_design_box(tmp_path):
    proc = pressor(
        "sil",
        "--controller",
        "smith",
        "--schedule",
        "oracle",
        "--duration",
        "60",
        "--rrd",
        "s.rrd",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    cols = rrd_columns(tmp_path / "s.rrd")
    for used_entity, device_entity in (
        ("/controller/rho/K", "/schedule/K"),
        ("/controller/rho/T_s", "/schedule/T_s"),
        ("/controller/rho/tau_s", "/schedule/tau_s"),
    ):
        used, device = cols[used_entity], cols[device_entity]
        stepped = [t for t, v in used.items() if not math.isnan(v)]
        assert len(stepped) > 0.9 * len(used)
        # the device's values lie inside the Smith clamp ranges and move slower than its rate
        # limits, so what it used is what the device sent
        assert all(used[t] == pytest.approx(device[t], rel=1e-6) for t in stepped)
    assert BOX_ENTITIES[0][0] not in cols  # no design box for a predictor without one


def test_sil_recording_holds_the_true_map_beside_the_noisy_measured_one(tmp_path):
    (tmp_path / "noisy.toml").write_text(
        'name = "noisy"\nduration_s = 60.0\n[patient]\nmode = "nonlinear"\n'
        "[target]\nstep_mmhg = 20.0\n[sensor]\nnoise_std_mmhg = 2.0\n"
    )
    proc = pressor(
        "sil", "--controller", "pi", "--scenario", "noisy.toml", "--rrd", "n.rrd", cwd=tmp_path
    )
    assert proc.returncode in (0, 1), proc.stderr
    cols = rrd_columns(tmp_path / "n.rrd")
    true, measured = cols["/patient/map_true_mmhg"], cols["/patient/map_mmhg"]
    assert sorted(true) == sorted(measured) == list(range(600))
    noise = [measured[k] - true[k] for k in range(600)]
    spread = (sum(e * e for e in noise) / len(noise)) ** 0.5
    assert 1.5 < spread < 2.5  # the monitor's 2 mmHg noise, absent from the true MAP
    assert max(abs(true[k + 1] - true[k]) for k in range(599)) < 0.5  # smooth: no noise in it
