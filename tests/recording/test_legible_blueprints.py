"""Every plot of every problem's default layout states its unit and keeps its legend off the data.

Rerun 0.41's time-series view has no y-axis title, so the view name is the axis name: it must carry the
unit in brackets. A legend is either hidden (the colours are then named in the view name) or pinned to
a corner by :func:`workbench.recording.blueprint.plot_view`; the event log hides the entity-path column.
"""

from __future__ import annotations

import numpy as np
import pytest
import rerun.blueprint as rrb

from workbench.recording import layout
from workbench.recording.blueprint import events_view, has_unit, plot_view, standard_blueprint, tab, time_window


def _walk(node):
    """Every view below a blueprint / container (depth first)."""
    if isinstance(node, rrb.Blueprint):
        yield from _walk(node.root_container)
    elif isinstance(node, rrb.Container):
        for c in node.contents:
            yield from _walk(c)
    else:
        yield node


def _time_series(bp) -> list:
    return [v for v in _walk(bp) if v.class_identifier == "TimeSeries"]


def _blueprints():
    from workbench.problems.droptest.recording import droptest_blueprint
    from workbench.problems.entry.recording import entry_blueprint
    from workbench.problems.entry.recording_mc import validation_blueprint
    from workbench.problems.meads.recording import meads_blueprint
    from workbench.problems.meads.recording_mc import trade_blueprint, truth_mc_blueprint
    from workbench.problems.post2.recording import post2_blueprint

    impact = {"eye": np.array([4.0, 0.0, 1.0]), "look": np.zeros(3), "up": np.array([0.0, 0.0, 1.0])}
    impact |= {"t0": 1.5, "t1": 2.0, "span": (-0.5, 2.3)}
    impact |= {"stroke_lo": 0.0, "stroke_hi": 1.0}
    triads = ["BP", "PYBP"]
    residuals = [*triads, "gyro", "zupt", "odometer", "gun1.range", "gun1.rate"]
    return {
        "droptest (generic)": droptest_blueprint(residuals, triads=triads),
        "droptest (after the run)": droptest_blueprint(residuals, impact, triads),
        "entry (generic)": entry_blueprint(),
        "entry (after the run)": entry_blueprint(descent=(175.0, 262.0)),
        "entry validation": validation_blueprint(),
        "meads": meads_blueprint(("P1", "P2", "P3", "P4", "P5", "P6", "P7"), 2),
        "meads trade study": trade_blueprint(),
        "meads truth Monte Carlo": truth_mc_blueprint((-3050, -225)),
        "post2": post2_blueprint(
            ["position", "velocity", "j2"],
            ["gravity"],
            True,
            residual_components={"gravity": ("value",)},
            observation_units={"gravity": "m/s^2"},
            schedules=["gravity"],
            has_events=True,
        ),
        "standard": standard_blueprint(plots=[("altitude [m]", layout.plot_path("altitude"))]),
    }


@pytest.mark.parametrize("name", list(_blueprints()))
def test_every_plot_names_its_unit_and_keeps_its_legend_off_the_data(name):
    views = _time_series(_blueprints()[name])
    assert views, name
    for v in views:
        assert has_unit(str(v.name)), f"{name}: view {v.name!r} has no [unit]"
        legend = v.properties.get("PlotLegend")
        assert legend is not None, f"{name}: view {v.name!r} keeps the default legend (over the data)"


def test_droptest_bounded_plots_have_an_impact_zoom_beside_the_whole_drop():
    from workbench.problems.droptest.recording import droptest_blueprint

    impact = {"eye": np.array([4.0, 0.0, 1.0]), "look": np.zeros(3), "up": np.array([0.0, 0.0, 1.0])}
    impact |= {"t0": 1.5, "t1": 2.0, "span": (-0.5, 2.3)}
    bp = droptest_blueprint(["BP", "gyro", "zupt"], impact | {"stroke_lo": 0.0, "stroke_hi": 1.0}, ["BP"])
    views = _time_series(bp)
    pos_x = [v for v in views if str(v.origin) == layout.join(layout.DROPTEST_PLOT_POSITION, "x")]
    zoomed = [v for v in pos_x if "VisibleTimeRanges" in v.properties]
    assert len(pos_x) == 2 and len(zoomed) == 1  # whole drop + impact window
    rng = zoomed[0].properties["VisibleTimeRanges"].ranges.as_arrow_array().to_pylist()[0]["range"]
    assert (rng["start"], rng["end"]) == (1_500_000_000, 2_000_000_000)
    assert "TimeAxis" in zoomed[0].properties  # the x axis opens on the window too
    # no view mixes the 12 position series any more: each axis has its own view
    assert not [v for v in views if str(v.origin) == layout.DROPTEST_PLOT_POSITION]


def test_entry_agl_views_are_fixed_on_the_descent():
    from workbench.problems.entry.recording import descent_window, entry_blueprint

    window = descent_window(
        {
            "event_table": [
                {"event": "EIP", "t_s": 0.0},
                {"event": "PDD", "t_s": 180.0},
                {"event": "Last data", "t_s": 262.0},
            ]
        }
    )
    assert window == (175.0, 262.0)
    assert descent_window({"event_table": [{"event": "EIP", "t_s": 0.0}]}) is None
    agl = [v for v in _time_series(entry_blueprint(descent=window)) if str(v.origin) == layout.ENTRY_PLOT_ALTITUDE_AGL]
    assert len(agl) == 2 and all({"VisibleTimeRanges", "TimeAxis"} <= set(v.properties) for v in agl)


def test_plot_view_refuses_a_name_without_unit_and_sets_the_legend():
    with pytest.raises(ValueError, match="unit"):
        plot_view("stroke", "/plots/stroke")
    hidden = plot_view("stroke [m]", "/plots/stroke").properties["PlotLegend"]
    assert hidden.visible.as_arrow_array().to_pylist() == [False]
    shown = plot_view("NIS [-]", "/plots/nis", legend="RightTop").properties["PlotLegend"]
    assert shown.visible.as_arrow_array().to_pylist() == [True]
    with pytest.raises(ValueError):
        time_window(2.0, 1.0)
    assert tab("stroke [m]", plot_view("stroke [m]", "/plots/stroke")).name == "stroke [m]"


def test_events_view_hides_the_entity_path_column():
    cols = events_view().properties["TextLogColumns"]
    kinds = cols.text_log_columns.as_arrow_array().to_pylist()
    hidden = [c["kind"] for c in kinds if not c["visible"]]
    assert hidden == [1]  # TextLogColumnKind.EntityPath
    timelines = {c["timeline"]: c["visible"] for c in cols.timeline_columns.as_arrow_array().to_pylist()}
    assert timelines[layout.TIME] and not any(v for k, v in timelines.items() if k != layout.TIME)


def test_meads_views_with_many_series_name_their_colours_instead_of_a_legend():
    """The scale factors (7 ports × passes, ±3σ, truth), the density and the per-port pressures had a
    legend over their curves; with a truth the density view shows the error against it [%]."""
    from workbench.problems.meads.recording import meads_blueprint

    ports = ("P1", "P2", "P3", "P4", "P5", "P6", "P7")
    for truth in (True, False):
        views = {str(v.origin): v for v in _time_series(meads_blueprint(ports, 2, truth))}
        for origin in (
            layout.plot_path("scale_factors"),
            layout.plot_path("density"),
            layout.join(layout.MEADS_PLOT_PORTS, "P1"),
        ):
            legend = views[origin].properties["PlotLegend"]
            assert legend.visible.as_arrow_array().to_pylist() == [False], origin
        assert "P7 pink" in str(views[layout.plot_path("scale_factors")].name)
        assert ("[%]" in str(views[layout.plot_path("density")].name)) is truth


def test_post2_grid_titles_show_quantity_and_unit_whole():
    """A grid cell (three across the right column of a 1400 px window) shows about 22 characters of
    its title: the post2 grid views put the quantity and unit first and the colour key in the
    scorecard, so the title up to its unit fits."""
    from workbench.problems.post2.recording import PLOT_KEY_MD, post2_blueprint

    bp = post2_blueprint(
        ["position", "velocity", "attitude", "body_rates"],
        ["acceleration"],
        True,
        residual_components={"acceleration": ("ax", "ay", "az")},
        observation_units={"acceleration": "m/s^2"},
    )
    grids = [c for c in _containers(bp) if isinstance(c, rrb.Grid)]
    assert len(grids) == 5
    for g in grids:
        for v in g.contents:
            name = str(v.name)
            assert name.index("]") + 1 <= 24, name
    assert "±3σ" in PLOT_KEY_MD and "truth" in PLOT_KEY_MD


def _containers(node):
    if isinstance(node, rrb.Blueprint):
        yield from _containers(node.root_container)
    elif isinstance(node, rrb.Container):
        yield node
        for c in node.contents:
            yield from _containers(c)


def test_meads_port_pressure_gets_the_full_height_of_its_tab():
    """Three views stacked in a port tab left each one y label: the pressure has its own column."""
    from workbench.problems.meads.recording import meads_blueprint

    bp = meads_blueprint(("P1", "P2"), 2)
    ports = [c for c in _containers(bp) if str(c.name) in ("P1", "P2")]
    assert len(ports) == 2
    for c in ports:
        assert isinstance(c, rrb.Horizontal)
        left, right = c.contents
        assert left.class_identifier == "TimeSeries" and "[Pa]" in str(left.name)
        assert isinstance(right, rrb.Vertical) and len(right.contents) == 2


def test_entry_profile_names_state_the_drawn_scale():
    from workbench.problems.entry.recording import PROFILE_SCALE, entry_blueprint

    names = [str(v.name) for v in _walk(entry_blueprint()) if v.class_identifier == "2D"]
    for q in ("density", "pressure", "temperature", "wind"):
        (n,) = [x for x in names if x.startswith(q)]
        assert f"y = {PROFILE_SCALE[q]:g}·km" in n


def _labelled_ticks(lo: float, hi: float, px: float) -> list[float]:
    """The y labels a time-series view ``px`` high over [lo, hi] shows: the multiples of the smallest
    power of ten whose ticks are ``LABEL_SPACING_PX`` apart (Rerun 0.41's plot)."""
    from workbench.recording.blueprint import LABEL_SPACING_PX

    step = 10.0 ** np.ceil(np.log10((hi - lo) * LABEL_SPACING_PX / px))
    return [k * step for k in range(int(np.ceil(lo / step - 1e-9)), int(np.floor(hi / step + 1e-9)) + 1)]


@pytest.mark.parametrize(
    ("lo", "hi"),
    [(-5202.0, 5202.0), (-75.3, 75.3), (-377.0, 377.0), (0.0, 0.532), (-3.74, 3.80), (3.0, 3.0), (-204.0, 119.0)],
)
@pytest.mark.parametrize("px", [130.0, 150.0, 400.0])
def test_legible_range_holds_the_data_and_three_labelled_ticks(lo, hi, px):
    from workbench.recording.blueprint import legible_range

    a, b = legible_range(lo, hi, min_px=px)
    assert a < lo and b > hi
    for h in (px, 1.3 * px):  # at least min_px high: three labels or more
        assert len(_labelled_ticks(a, b, h)) >= 3, (lo, hi, px, h, a, b)


def test_legible_range_of_the_slant_out_residual_shows_its_3sigma_band():
    """±5.2 km in a 150 px view: the viewer's fit labels only "0"; the range ±10.5 km labels
    −10 000, 0, 10 000 with the ±3σ band inside, at half the height."""
    from workbench.recording.blueprint import legible_range

    assert _labelled_ticks(-5460.0, 5460.0, 150.0) == [0.0]
    a, b = legible_range(-5202.0, 5202.0, min_px=150.0)
    assert (a, b) == pytest.approx((-10500.0, 10500.0))
    assert _labelled_ticks(a, b, 150.0) == [-10000.0, 0.0, 10000.0]
    with pytest.raises(ValueError):
        legible_range(1.0, 0.0)
    with pytest.raises(ValueError):
        legible_range(0.0, 1.0, min_px=50.0)


def test_plot_view_span_opens_the_x_axis_and_keeps_the_data():
    v = plot_view("a [m]", "/plots/a", span=(3.0, 4.5), y_range=(-1.0, 2.0))
    assert v.properties["TimeAxis"].view_range.as_arrow_array().to_pylist() == [
        {"start": 3_000_000_000, "end": 4_500_000_000}
    ]
    assert "VisibleTimeRanges" not in v.properties  # all data, only the axis opened on the span
    assert v.properties["ScalarAxis"].range.as_arrow_array().to_pylist() == [[-1.0, 2.0]]
    with pytest.raises(ValueError):
        plot_view("a [m]", "/plots/a", span=(3.0, 4.5), window=(3.0, 4.0))
    with pytest.raises(ValueError):
        plot_view("a [m]", "/plots/a", span=(4.5, 3.0))


def test_entry_descent_view_leaves_the_3sigma_ellipsoid_out_and_names_its_size():
    """The smoothed 3σ ellipsoid is kilometres wide at the end of the descent: the Descent view's
    camera (tens of metres from the vehicle) sits inside it. That view shows its size as text;
    the Entry view draws it, without the text and without the dispersion cloud."""
    from workbench.problems.entry.recording import DESCENT_EYE, entry_blueprint, sigma_label

    views = {str(v.name): [str(c) for c in v.contents] for v in _walk(entry_blueprint()) if v.class_identifier == "3D"}
    descent, entry = views["Descent (at the vehicle)"], views["Entry (site frame, km scale)"]
    # the ellipsoid's subtree: the ellipsoid and its name 8 km above it (the Entry view's)
    sub = layout.subtree(layout.UNCERTAINTY)
    assert "- " + sub in descent and "- " + layout.ENTRY_UNCERTAINTY_LABEL not in descent
    assert "- " + layout.ENTRY_UNCERTAINTY_LABEL in entry and not {"- " + layout.UNCERTAINTY, "- " + sub} & set(entry)
    assert "- " + layout.subtree(layout.DISPERSION) in entry
    assert "- " + layout.VEHICLE_MARKER in descent and "- " + layout.VEHICLE_MARKER not in entry
    assert float(np.linalg.norm(DESCENT_EYE)) < 123.0  # inside the shipped run's smallest 3σ half-axis
    assert sigma_label(np.array([[123.4, 38223.0, 9935.0]])) == ["3σ ellipsoid ±38.2 km × ±9.94 km × ±123 m"]


def test_entry_residual_views_get_a_labelled_range_holding_the_3sigma_band():
    from types import SimpleNamespace

    from workbench.problems.entry.recording import entry_blueprint, residual_ranges

    n = 50
    res = SimpleNamespace(
        t=np.linspace(225.0, 262.0, n),
        y=np.linspace(-204.0, 119.0, n)[:, None],
        S=np.full((n, 1, 1), (5202.0 / 3.0) ** 2),
    )
    empty = SimpleNamespace(t=np.zeros(0), y=np.zeros((0, 3)), S=np.zeros((0, 3, 3)))
    ranges = residual_ranges(SimpleNamespace(smoothed_residuals={"slant_out": res, "velocity_out": empty}))
    assert set(ranges) == {"slant_out"}
    a, b = ranges["slant_out"]
    assert a < -5202.0 and b > 5202.0 and len(_labelled_ticks(a, b, 130.0)) >= 3
    bp = entry_blueprint(descent=(175.0, 262.0), residual_y=ranges)
    (view,) = [v for v in _time_series(bp) if str(v.origin) == layout.ENTRY_RESIDUAL_SLANT_OUT]
    assert view.properties["ScalarAxis"].range.as_arrow_array().to_pylist() == [[a, b]]


def _impact_result(ns, rl, n: int = 20):
    """A drop result at the max stroke (step 9): the shipped lander with its CM 1.2 m above a level
    ramp (z = 0), level, its closest body point 0.236 m above the ramp."""
    from workbench.io.assets import assets_dir
    from workbench.problems.droptest.lander import load_lander

    lander = load_lander(assets_dir() / "landers" / "mer_drop_lander.toml")
    x = np.zeros((n, rl.N_X))
    x[:, rl.SP] = [0.0, 0.0, 1.2]
    x[:, 12] = 1.0  # q_I_B = identity (xyzw)
    closest = np.tile([0.1, -0.2, 0.236], (n, 1))
    st = ns(
        contact=(5, 12),
        restitution_index=(4, 14),
        max=ns(distance=0.236, sigma=0.049, index=9),
        smoothed=ns(closest_point_I=closest, surface_point_I=closest * [1.0, 1.0, 0.0]),
        surface=ns(normal=np.array([0.0, 0.0, 1.0])),
        lander=lander,
    )
    return ns(stroke=st, smoothed=ns(x=x, t=np.linspace(1.0, 2.0, n)))


def test_droptest_impact_camera_reads_the_max_stroke_in_front_of_the_airbags():
    """The stroke segment ran inside the translucent lobes, seen almost end-on from 10 m (about 15 px):
    the Impact camera looks at it across the ramp, with the ramp normal up on screen, and its copy
    (the dimension line) lies on the camera's side of every lobe, as long as the segment."""
    from types import SimpleNamespace

    from workbench.problems.droptest import model as rl
    from workbench.problems.droptest.recording import (
        DIMENSION_CLEARANCE_M,
        airbags_at,
        impact_view,
        max_stroke_dimension,
    )

    res = _impact_result(SimpleNamespace, rl)
    view = impact_view(res)
    c, f = res.stroke.smoothed.closest_point_I[9], res.stroke.smoothed.surface_point_I[9]
    eye, look = view["eye"], view["look"]
    # seen side-on and large: the segment subtends > 2.5° at the camera (10 m away at 41° off its
    # axis it subtended 0.8°), and the camera's up is the ramp normal (the segment vertical on screen)
    a, b = c - eye, f - eye
    angle = np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))
    assert angle > 2.5
    np.testing.assert_allclose(view["up"], [0.0, 0.0, 1.0])
    d = (look - eye) / np.linalg.norm(look - eye)
    assert abs(d @ (f - c)) / np.linalg.norm(f - c) < 0.5  # not end-on
    # the dimension line: parallel, as long, every lobe point behind it as seen from the eye
    bags = airbags_at(res.stroke.lander, res.smoothed.x[9])
    dim = max_stroke_dimension(c, f, [0.0, 0.0, 1.0], bags, res.smoothed.x[9, rl.SP])
    np.testing.assert_allclose(dim["b"] - dim["a"], f - c, atol=1e-12)
    np.testing.assert_allclose(dim["eye"], eye)
    side = dim["side"]
    assert np.max((bags - c) @ side) <= dim["offset"] - DIMENSION_CLEARANCE_M + 1e-9
    assert (eye - dim["a"]) @ side > 0.0 and (eye - dim["b"]) @ side > 0.0
    # the label beside the line, off it
    mid = 0.5 * (dim["a"] + dim["b"])
    off = dim["label"] - mid
    assert np.linalg.norm(off) > 0.3 and abs(off @ (f - c)) < 1e-9


def test_droptest_nis_legend_stands_right_of_the_data():
    """The NIS legend (one colour per sensor, seven rows) covered the right end of the spikes: the
    view opens its x axis with room right of the data for it, the legend in that corner."""
    from workbench.problems.droptest.recording import droptest_blueprint

    impact = {"eye": np.array([4.0, 0.0, 1.0]), "look": np.zeros(3), "up": np.array([0.0, 0.0, 1.0])}
    impact |= {"t0": 1.5, "t1": 2.0, "span": (-0.5, 2.3), "stroke_lo": 0.0, "stroke_hi": 1.0}
    (nis,) = [
        v for v in _time_series(droptest_blueprint(["BP"], impact, ["BP"])) if str(v.origin) == layout.DROPTEST_PLOT_NIS
    ]
    legend = nis.properties["PlotLegend"]
    assert legend.visible.as_arrow_array().to_pylist() == [True]
    corner = legend.corner.as_arrow_array().to_pylist()[0]
    assert rrb.components.Corner2D(corner).name in ("RightTop", "RightBottom")
    rng = nis.properties["TimeAxis"].view_range.as_arrow_array().to_pylist()[0]
    start, end = rng["start"], rng["end"]
    span_ns = 2.8e9
    assert start == pytest.approx(-0.5e9) and end >= 2.3e9 + 0.3 * span_ns


def test_droptest_stroke_zoom_holds_the_max_stroke_band_with_labelled_ticks():
    """The zoomed stroke view: from the ramp (0) to above the max stroke's +3σ, with 0.1 m ticks
    labelled (0 to 1.2 m labelled only 0 and 1 in a 1400 x 900 window)."""
    from types import SimpleNamespace

    from workbench.problems.droptest import model as rl
    from workbench.problems.droptest.recording import STROKE_VIEW_PX, impact_view

    view = impact_view(_impact_result(SimpleNamespace, rl))
    lo, hi = view["stroke_lo"], view["stroke_hi"]
    assert lo < 0.0 and hi > 0.236 + 3 * 0.049 and hi < 1.0
    ticks = _labelled_ticks(lo, hi, STROKE_VIEW_PX)
    assert len(ticks) >= 5 and ticks[1] - ticks[0] == pytest.approx(0.1)


def test_post2_views_open_on_what_they_draw():
    """A Huygens run lasts 2 h 13 min: the viewer opened its plots on a minute around the time
    cursor. Each state view opens on the run, each residual view on its observation's span, with
    a y range holding value ± 3σ (and truth) at labelled ticks."""
    from workbench.problems.post2.recording import Post2Drawer, post2_blueprint

    d = Post2Drawer(None, None, None)
    t = np.linspace(0.0, 267.8, 30)
    d.view_range(layout.residual_path("accel_entry", "ax"), t, np.full(30, 3.8), np.full(30, -3.7))
    d.view_range(layout.residual_path("accel_entry", "ax"), t + 10.0, np.array([np.nan, 4.0]))
    assert d.spans[layout.residual_path("accel_entry", "ax")] == (0.0, pytest.approx(277.8))
    assert d.y_ranges[layout.residual_path("accel_entry", "ax")] == (-3.7, 4.0)
    bp = post2_blueprint(
        ["position"],
        ["accel_entry"],
        True,
        residual_components={"accel_entry": ("ax",)},
        observation_units={"accel_entry": "m/s^2"},
        span=(0.0, 8000.0),
        spans=d.spans,
        y_ranges={layout.residual_path("accel_entry", "ax"): (-10.5, 10.5)},
    )
    axes = {
        str(v.origin): v.properties["TimeAxis"].view_range.as_arrow_array().to_pylist()[0] for v in _time_series(bp)
    }
    assert axes[layout.plot_path("position_error/x")] == {"start": 0, "end": 8_000_000_000_000}
    assert axes[layout.residual_path("accel_entry", "ax")]["end"] == round(277.8e9)
    (res,) = [v for v in _time_series(bp) if str(v.origin) == layout.residual_path("accel_entry", "ax")]
    assert res.properties["ScalarAxis"].range.as_arrow_array().to_pylist() == [[-10.5, 10.5]]


def test_entry_plots_open_on_the_run_and_the_residuals_on_the_radar():
    """The entry's time plots opened on about a minute around the time cursor (the end of a 277 s
    run): each opens on the run, the residual and radar views on the radar's span."""
    from types import SimpleNamespace

    from workbench.problems.entry.recording import entry_blueprint, residual_spans, run_span

    span = run_span({"event_table": [{"event": "First data", "t_s": -15.0}, {"event": "BSR", "t_s": 262.48}]})
    assert span == (-15.0, 262.48) and run_span({"event_table": []}) is None
    res = SimpleNamespace(t=np.linspace(225.5, 262.4, 5))
    rs = residual_spans(SimpleNamespace(smoothed_residuals={"slant_out": res, "slant_range": SimpleNamespace(t=[1.0])}))
    assert rs == {"slant_out": (225.5, 262.4)}
    views = _time_series(entry_blueprint(descent=(175.0, 262.48), span=span, residual_span=rs))
    axes = {
        str(v.name): v.properties["TimeAxis"].view_range.as_arrow_array().to_pylist()[0]
        for v in views
        if "TimeAxis" in v.properties
    }
    amr = [a for n, a in axes.items() if n.startswith("altitude AMR")]
    assert amr == [{"start": -15_000_000_000, "end": 262_480_000_000}]
    radar_ns = pytest.approx({"start": 225_500_000_000, "end": 262_400_000_000}, abs=1)  # seconds -> ns
    assert axes["slant-out residual [m] — blue, grey ±3σ"] == radar_ns
    radar = [a for n, a in axes.items() if n.startswith("slant-out [m]")]
    assert radar == [radar_ns]
    # every time plot but the per-member dispersion views (timeline 'sample') opens on a known span
    timed = [v for v in views if "per member" not in str(v.name)]
    assert all("TimeAxis" in v.properties for v in timed)
    # measured vs predicted radar: a tab each (stacked three in the residual row, each too short for a y label)
    (radar_tabs,) = [c for c in _containers(entry_blueprint()) if str(c.name) == "radar meas vs pred"]
    assert isinstance(radar_tabs, rrb.Tabs) and len(radar_tabs.contents) == 3


def test_meads_plots_open_on_the_pressure_span():
    """A 293 s MEADS run opened its plots on about a minute around the time cursor: the port views
    open on the run, the air-data views on the span above the q∞ threshold."""
    from workbench.problems.meads.recording import meads_blueprint

    views = _time_series(meads_blueprint(("P1", "P2"), 2, True, span=(0.0, 292.625), air_span=(60.0, 280.0)))
    assert views
    for v in views:
        rng = v.properties["TimeAxis"].view_range.as_arrow_array().to_pylist()[0]
        port = str(v.name).startswith(("P1", "P2"))
        want = {"start": 0, "end": 292_625_000_000} if port else {"start": 60_000_000_000, "end": 280_000_000_000}
        assert rng == pytest.approx(want, abs=1), v.name
    assert all("TimeAxis" not in v.properties for v in _time_series(meads_blueprint(("P1",), 0)))


def test_y_range_only_where_the_viewer_labels_fewer_than_three_ticks():
    from types import SimpleNamespace

    from workbench.problems.meads.recording import AIR_DATA_VIEW_PX, PORT_FIT_VIEW_PX, meads_blueprint, view_y_ranges
    from workbench.recording.blueprint import labelled_ticks, y_range_if_needed

    assert labelled_ticks(12.0, 28.0, 180.0) == [20.0]  # α over the high-q∞ span: one label
    assert y_range_if_needed(-55.0, 31.0, 180.0) is None  # ρ error: the viewer labels every 10 %
    a, b = y_range_if_needed(12.0, 28.0, 180.0)
    assert a < 12.0 and b > 28.0 and len(labelled_ticks(a, b, 180.0)) >= 3
    res = layout.residual_path("pressure", "P1")
    drawn = {layout.plot_path("alpha_deg"): (12.0, 28.0), layout.plot_path("density"): (-55.0, 31.0), res: (-90, 90)}
    calls = {}

    def value_range(origin, t0, t1):
        calls[origin] = (t0, t1)
        return drawn.get(origin)

    ranges = view_y_ranges(SimpleNamespace(value_range=value_range), ("P1",), 2, (60.0, 280.0))
    assert set(ranges) == {layout.plot_path("alpha_deg"), res}
    assert calls[layout.plot_path("alpha_deg")] == (60.0, 280.0) and calls[res] == (None, None)
    assert layout.meads_ekf_innovation_path(2, "P1") in calls
    assert len(labelled_ticks(*ranges[layout.plot_path("alpha_deg")], AIR_DATA_VIEW_PX)) >= 3
    assert len(labelled_ticks(*ranges[res], PORT_FIT_VIEW_PX)) >= 3
    views = {str(v.origin): v for v in _time_series(meads_blueprint(("P1",), 2, True, y_ranges=ranges))}
    assert views[res].properties["ScalarAxis"].range.as_arrow_array().to_pylist() == [list(ranges[res])]


def test_droptest_bounded_axes_get_a_tab_each_and_labelled_y_ranges():
    """Three axes stacked in the plot row were each too low for more than one y label: a tab per
    axis (whole drop beside the impact zoom), y ranges fixed where the viewer would label fewer than
    three ticks, over the impact window for the zoom."""
    from types import SimpleNamespace

    from workbench.problems.droptest.recording import BOUNDED_VIEW_PX, bounded_y_ranges, droptest_blueprint

    x = layout.join(layout.DROPTEST_PLOT_POSITION, "x")
    drawn = {(x, None, None): (-0.7, 1.9), (x, 1.5, 2.0): (-0.08, 0.09)}
    rec = SimpleNamespace(value_range=lambda o, t0=None, t1=None: drawn.get((o, t0, t1)))
    impact = {"eye": np.array([4.0, 0.0, 1.0]), "look": np.zeros(3), "up": np.array([0.0, 0.0, 1.0])}
    impact |= {"t0": 1.5, "t1": 2.0, "span": (-0.5, 2.3)}
    whole, zoom = bounded_y_ranges(rec, impact | {"stroke_lo": 0.0, "stroke_hi": 1.0})
    assert set(whole) == {x} and set(zoom) == {x}
    for r in (whole[x], zoom[x]):
        assert len(_labelled_ticks(*r, BOUNDED_VIEW_PX)) >= 3
    bp = droptest_blueprint(["BP"], impact | {"stroke_lo": 0.0, "stroke_hi": 1.0}, ["BP"], whole, zoom)
    (pos,) = [c for c in _containers(bp) if str(c.name) == "position [m]"]
    assert isinstance(pos, rrb.Tabs) and [str(c.name) for c in pos.contents] == ["x", "y", "z"]
    views = [v for v in _time_series(bp) if str(v.origin) == x]
    ranges = sorted(v.properties["ScalarAxis"].range.as_arrow_array().to_pylist()[0] for v in views)
    assert ranges == sorted([list(whole[x]), list(zoom[x])])
    (gyro,) = [c for c in _containers(bp) if str(c.name) == "gyro scale [%]"]
    assert isinstance(gyro, rrb.Horizontal) and len(gyro.contents) == 3
