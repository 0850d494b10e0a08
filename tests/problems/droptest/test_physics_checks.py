"""Physics cross-checks of a drop test (issue 26): each fires on a mutated input and stays OK on the
clean synthetic telemetry of the shipped ``droptest`` scenario (session fixture ``droptest_run``).

Mutations are planted in a COPY of the run's telemetry (or of its scenario settings): sensor axes,
signs and dead channels against gravity while hanging; the declared hanging position against the
first contact; the declared lander height against the IMU's rigid impact (and the note on the
declared body vertex the max stroke rests on); an IMU file ending inside the contact (outputs
undefined, never a number); a diverged filter or a dead triad ending in a clear error instead of a
traceback.  The timing check
(an IMU acquisition filter declared causal when it was zero-phase, with ranging) is in the slow tier.
"""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core.rotation import dcm_to_quat
from workbench.estimation.health import ERROR, OK, WARNING
from workbench.io.assets import assets_dir
from workbench.problems.droptest import model as rl
from workbench.problems.droptest import pipeline as dt
from workbench.problems.droptest.lander import load_lander
from workbench.problems.droptest.physics import diagnose_axes, hanging_checks, max_stroke_note
from workbench.problems.droptest.problem import key_moments
from workbench.problems.droptest.stroke import max_stroke, stroke_history
from workbench.problems.droptest.surface import ramp_surface
from workbench.problems.droptest.telemetry import load_drop_telemetry

Rows = list[list[str]]


def _copy(run, dst: Path) -> dict[str, Path]:
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("imu.csv", "3dm.csv", "events.csv", "setup.toml"):
        shutil.copy(run.telemetry_dir / f, dst / f)
    return run.telemetry_paths(dst)


def _edit_csv(path: Path, fn: Callable[[list[str], np.ndarray], np.ndarray]) -> None:
    """Rewrite a telemetry CSV through ``fn(header_names, values (n, k)) -> values``."""
    lines = path.read_text(encoding="utf-8").splitlines()
    h = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    names = [c.split(" [")[0] for c in lines[h].split(",")]
    x = np.array([[float(v) for v in ln.split(",")] for ln in lines[h + 1 :] if ln])
    x = fn(names, x)
    body = [",".join(repr(float(v)) for v in row) for row in x]
    path.write_text("\n".join([*lines[: h + 1], *body]) + "\n", encoding="utf-8")


def _flip(*cols: str):
    def fn(names, x):
        for c in cols:
            x[:, names.index(c)] *= -1.0
        return x

    return fn


def _swap(a: str, b: str):
    def fn(names, x):
        i, j = names.index(a), names.index(b)
        x[:, [i, j]] = x[:, [j, i]]
        return x

    return fn


def _const(*cols: str, value: float = 0.0):
    def fn(names, x):
        for c in cols:
            x[:, names.index(c)] = value
        return x

    return fn


def _checks(health: dict, prefix: str) -> dict[str, dict]:
    return {c["name"]: c for c in health["checks"] if c["name"].startswith(prefix)}


@pytest.fixture(scope="module")
def clean_tel(droptest_run):
    return load_drop_telemetry(droptest_run.settings, droptest_run.telemetry_paths())


def _hanging(run, tmp_path, file: str, fn) -> dict[str, object]:
    paths = _copy(run, tmp_path)
    _edit_csv(paths["imu" if file == "imu" else "attitude_3dm"], fn)
    tel = load_drop_telemetry(run.settings, paths)
    return {c.name: c for c in hanging_checks(tel, run.settings)}


# ------------------------------------------------------------------ sensor axes against gravity


def test_hanging_checks_ok_on_clean_run(droptest_run, clean_tel):
    checks = hanging_checks(clean_tel, droptest_run.settings)
    names = {c.name for c in checks}
    assert {f"units.hanging.{n}" for n in clean_tel.triads} <= names
    assert {"units.hanging.3dm_up", "units.hanging.3dm_dip", "units.hanging.gyro"} <= names
    assert all(c.status == OK for c in checks), [(c.name, c.message) for c in checks if c.status != OK]


def test_triad_axis_sign_flip_named(droptest_run, tmp_path):
    c = _hanging(droptest_run, tmp_path, "imu", _flip("BP.y"))["units.hanging.BP"]
    assert c.status == ERROR
    assert "axis y looks sign-flipped" in c.message and "BP.y" in c.message and "imu.csv" in c.message


def test_triad_axes_swapped_named(droptest_run, tmp_path):
    c = _hanging(droptest_run, tmp_path, "imu", _swap("PYBP.y", "PYBP.z"))["units.hanging.PYBP"]
    assert c.status == ERROR
    assert "y and z swapped" in c.message


def test_dead_triad_named_and_run_ends_in_error_verdict(droptest_run, tmp_path):
    paths = _copy(droptest_run, tmp_path)
    _edit_csv(paths["imu"], _const("PXBP.x", "PXBP.y", "PXBP.z"))
    res = dt.run_droptest(droptest_run.settings, paths)
    c = _checks(res.summary["health"], "units.hanging.PXBP")["units.hanging.PXBP"]
    assert c["status"] == ERROR and "all zeros" in c["message"] and "PXBP.x" in c["message"]


def test_3dm_up_reversed_and_vectors_swapped(droptest_run, tmp_path):
    c = _hanging(droptest_run, tmp_path / "a", "3dm", _flip("up.x", "up.y", "up.z"))
    assert c["units.hanging.3dm_up"].status == ERROR and "reversed" in c["units.hanging.3dm_up"].message
    assert c["units.hanging.3dm_dip"].status == OK  # the dip is judged against the triads, not the bad 'up'

    def swap_vectors(names, x):
        i = [names.index(f"up.{a}") for a in "xyz"]
        j = [names.index(f"mag.{a}") for a in "xyz"]
        x[:, i + j] = x[:, j + i]
        return x

    c = _hanging(droptest_run, tmp_path / "b", "3dm", swap_vectors)
    assert c["units.hanging.3dm_up"].status == ERROR and "swapped" in c["units.hanging.3dm_up"].message


def test_reversed_magnetic_field_named(droptest_run, tmp_path):
    c = _hanging(droptest_run, tmp_path, "3dm", _flip("mag.x", "mag.y", "mag.z"))["units.hanging.3dm_dip"]
    assert c.status == ERROR and "reversed" in c.message and "magnetic_field_spf" in c.message


def test_stuck_gyro_named(droptest_run, tmp_path):
    c = _hanging(droptest_run, tmp_path, "imu", _const("gyro.x", "gyro.y", "gyro.z"))["units.hanging.gyro"]
    assert c.status == ERROR and "stuck" in c.message and "gyro.x" in c.message


def test_diagnose_axes_prefers_simplest_mistake():
    up = np.array([0.0, 0.5, 0.866])
    assert diagnose_axes(up * [1, -1, 1], up, 3.0) == "axis y looks sign-flipped"
    assert diagnose_axes(up[[0, 2, 1]], up, 3.0) == "y and z swapped"
    assert diagnose_axes(np.array([0.3, -0.2, 0.9]), up, 3.0) is None


# ------------------------------------------------------------------ rig geometry and key moments


def test_first_contact_geometry_ok_clean_error_hanging_moved(droptest_run, droptest_result, tmp_path):
    geo = _checks(droptest_result.summary["health"], "geometry.")["geometry.first_contact"]
    assert geo["status"] == OK, geo["message"]
    paths = _copy(droptest_run, tmp_path)
    text = paths["setup"].read_text(encoding="utf-8")

    def up1(m):
        v = [float(s) for s in m.group(1).split(",")]
        v[2] += 1.0
        return "position_m = [" + ", ".join(f"{a:.6f}" for a in v) + "]"

    paths["setup"].write_text(re.sub(r"position_m = \[([^\]]*)\]", up1, text), encoding="utf-8")
    res = dt.run_droptest(droptest_run.settings, paths)
    geo = _checks(res.summary["health"], "geometry.")["geometry.first_contact"]
    assert res.summary["health"]["verdict"] == ERROR
    assert geo["status"] == ERROR and "[hanging] position_m" in geo["message"]
    # user data may leave the bag pressures out of the lander asset: the band allows a lobe radius
    lander = replace(droptest_run.settings.lander, pressure_pa=None, ambient_pressure_pa=None)
    res = dt.run_droptest(replace(droptest_run.settings, lander=lander), paths)
    geo = _checks(res.summary["health"], "geometry.")["geometry.first_contact"]
    assert geo["status"] == ERROR and "bag pressures not declared, up to a lobe radius (1.000 m)" in geo["message"]
    assert geo["bound"][0] < -1.0


def test_first_contact_is_judged_at_the_measured_first_touch(droptest_result, droptest_truth):
    """The bags' first touch in the IMU (the last free-fall sample before the 2 g onset) is the
    truth's first contact within a few samples, and the first-contact clearance is judged there: a
    lobe just touching, whatever the impact (by the 2 g onset a vertex-first impact has three bags'
    corner lobes pressed in tens of cm)."""
    from workbench.problems.droptest.physics import measured_impact, measured_touch

    tel = droptest_result.telemetry
    onset = measured_impact(tel)[0]
    touch = measured_touch(tel, onset)
    assert touch is not None and touch < onset
    assert abs(touch - droptest_truth["events"]["first_contact"]) < 0.003
    geo = _checks(droptest_result.summary["health"], "geometry.")["geometry.first_contact"]
    assert "measured first touch" in geo["message"] and "pressed in at 0.25 g" in geo["message"]


def test_max_stroke_clearance_allows_the_structures_give_under_the_peak_load(droptest_result):
    """A full stroke's vertex reaches into the ramp as far as the structure gives under the peak
    load, m·|a|max/k with the asset's ``contact_stiffness_n_per_m``: the clearance's lower bound."""
    from workbench.problems.droptest.physics import structural_give

    res = droptest_result
    depth, peak_g = structural_give(res.smoothed, res.telemetry, res.stroke.lander)
    lander = res.stroke.lander
    assert lander.contact_stiffness == 2.0e7  # the asset's default, the truth simulator's too
    assert depth == pytest.approx(lander.mass * peak_g * 9.80665 / lander.contact_stiffness, rel=1e-9)
    clear = _checks(res.summary["health"], "max_stroke.")["max_stroke.clearance"]
    assert clear["bound"][0] == pytest.approx(-3.0 * res.stroke.max.sigma - depth, abs=1e-6)
    assert "contact_stiffness_n_per_m" in clear["message"]


def test_full_stroke_ok_on_clean_run_and_a_lander_in_feet_is_an_error_naming_the_geometry(
    droptest_run, droptest_result, tmp_path
):
    """The body's dimensions declared in feet (height, base side and CM height × 3.281) move the
    closest declared vertex (vertex 2, a base corner) 1.3 m into the ramp while the IMU shows only
    the bags' jerk: a full stroke (by more than 3σ) the data contradict, ERROR naming the lander
    file's geometry."""
    full = _checks(droptest_result.summary["health"], "geometry.")["geometry.full_stroke"]
    assert full["status"] == OK and "no full stroke" in full["message"], full["message"]
    src = droptest_run.settings.lander_file
    text = Path(src).read_text(encoding="utf-8")
    feet = tmp_path / "lander.toml"
    for key, metres in (("height_m", "1.2"), ("base_side_m", "1.6"), ("cm_height_m", "0.40")):
        text, n = re.subn(rf"^{key} = {re.escape(metres)} ", f"{key} = {float(metres) * 3.281:.3f} ", text, flags=re.M)
        assert n == 1, key
    feet.write_text(text, encoding="utf-8")
    settings = replace(droptest_run.settings, lander=load_lander(feet), lander_file=feet)
    res = dt.run_droptest(settings, droptest_run.telemetry_paths())
    assert res.summary["max_stroke"]["distance_m"] < 0.0
    full = _checks(res.summary["health"], "geometry.")["geometry.full_stroke"]
    assert full["status"] == ERROR and "height_m" in full["message"] and "FULL STROKE" in full["message"], full[
        "message"
    ]
    # the clean run's note says the stroke rests on a declared vertex no sensor sees, and its gradient
    # predicts the stroke of that pose with the vertex moved (the same vertex stays the closest)
    note = next(n for n in droptest_result.summary["health"]["notes"] if n.startswith("max stroke"))
    assert "vertex 2, a base vertex" in note and "no sensor sees" in note and "height_m" in note, note
    grad = np.array([float(g) for g in re.search(r"∇ = \[([^\]]+)\]", note).group(1).split(",")])
    v_old = np.asarray(droptest_run.settings.lander.body.vertices[2], float)
    v_new = np.asarray(settings.lander.body.vertices[2], float)
    moved = res.summary["max_stroke"]["distance_m"] - droptest_result.summary["max_stroke"]["distance_m"]
    assert abs(moved - grad @ (v_new - v_old)) < 0.02 * abs(moved), (moved, grad @ (v_new - v_old))


def test_max_stroke_note_gradient_moves_the_stroke_of_a_moved_vertex():
    """The note's gradient of the stroke with respect to the closest declared vertex (body frame)
    predicts the stroke of the same pose with that vertex moved: apex pointing into the 60° ramp
    0.25 m away, the apex raised 0.1 m along body +z -> stroke 0.15 m (gradient −1 along +z)."""
    lander = load_lander(assets_dir() / "landers" / "mer_drop_lander.toml")
    surface = ramp_surface(angle_deg=60.0, nail_depth=0.3)
    n = surface.normal
    z_I = -n  # body +z (toward the apex) into the ramp; body +x along SPF X, which lies in the ramp plane
    x_I = np.array([1.0, 0.0, 0.0])
    q = dcm_to_quat(np.column_stack([x_I, np.cross(z_I, x_I), z_I]))
    apex = np.asarray(lander.body.vertices[3], float)
    p = surface.point + (0.25 + apex[2]) * n

    def stroke(verts):
        h = stroke_history(verts, p[None], q[None], np.zeros((1, 6, 6)), surface, faces_B=np.asarray(lander.body.faces))
        return h, max_stroke(np.zeros(1), h, lander.body)

    hist, ms = stroke(np.asarray(lander.body.vertices, float))
    x = np.zeros((1, rl.sizes(4)[0]))
    x[0, rl.SQ] = q
    note = max_stroke_note(
        SimpleNamespace(x=x), SimpleNamespace(max=ms, smoothed=hist, lander=lander), SimpleNamespace(lander_file="L")
    )
    assert ms.vertex == 3 and abs(ms.distance - 0.25) < 1e-9
    assert "max stroke 0.250" in note and "vertex 3, the apex ([0.000, 0.000, 0.800] m" in note, note
    per_m = float(re.search(r"by ([+-][0-9.]+) m per metre", note).group(1))
    assert per_m == -1.0
    raised = np.asarray(lander.body.vertices, float).copy()
    raised[3, 2] += 0.1
    assert abs(stroke(raised)[1].distance - (0.25 + per_m * 0.1)) < 1e-9


def test_rigid_impact_while_the_geometry_keeps_the_lander_clear_is_an_error(droptest_run, droptest_result, tmp_path):
    """A 3 ms, 100 g half-sine on every triad at the max-stroke time (the frame striking the ramp)
    while the declared geometry keeps the lander 0.24 m clear: ERROR naming the geometry keys."""
    paths = _copy(droptest_run, tmp_path)
    t_ms = droptest_result.summary["max_stroke"]["time_s"] + droptest_result.telemetry.group_delay_s

    def strike(names, x):
        t = x[:, names.index("time")]
        pulse = np.where(np.abs(t - t_ms) < 0.0015, 100.0 * np.cos(np.pi * (t - t_ms) / 0.003), 0.0)
        for tri in droptest_run.settings.accelerometer.triads:
            x[:, names.index(f"{tri}.z")] += pulse
        return x

    _edit_csv(paths["imu"], strike)
    res = dt.run_droptest(droptest_run.settings, paths)
    full = _checks(res.summary["health"], "geometry.")["geometry.full_stroke"]
    assert full["status"] == ERROR and "height_m" in full["message"], full["message"]
    assert full["value"] > full["bound"]


def test_ramp_angle_in_radians_named(droptest_run, droptest_result):
    ch = replace(droptest_run.settings.chamber, ramp_angle_deg=float(np.radians(60.0)))
    settings = replace(droptest_run.settings, chamber=ch)
    res = dt.run_droptest(settings, droptest_run.telemetry_paths())
    geo = _checks(res.summary["health"], "geometry.")["geometry.first_contact"]
    assert geo["status"] == ERROR and "looks like radians" in geo["message"]
    key_moments(res)  # a max stroke at the data end lies inside its window: no internal error


# ------------------------------------------------------------------ data ending inside the contact


def test_imu_ending_inside_contact_makes_outputs_undefined(droptest_run, droptest_result, tmp_path):
    clean = droptest_result.summary
    assert clean["restitution"]["e"] is not None and "undefined" not in clean["restitution"]
    t_cut = clean["contact"]["start_s"] + 0.1  # inside the compression, before the max stroke
    paths = _copy(droptest_run, tmp_path)
    _edit_csv(paths["imu"], lambda names, x: x[x[:, 0] <= t_cut])
    res = dt.run_droptest(droptest_run.settings, paths)
    s = res.summary
    assert s["restitution"]["e"] is None and s["restitution"]["sigma"] is None
    assert s["max_stroke"]["distance_m"] is None and "imu.csv" in s["max_stroke"]["undefined"]
    c = _checks(s["health"], "data.contact")["data.contact"]
    assert c["status"] == WARNING and "imu.csv" in c["message"] and "end at t =" in c["message"]
    md = dt.scorecard_markdown(s)
    assert "**undefined**" in md
    names = [m.name for m in key_moments(res)]
    assert "max_stroke" not in names and "rebound" not in names


def test_imu_ending_between_two_compressions_leaves_the_max_stroke_undefined(droptest_run, droptest_result, tmp_path):
    # the lander bounces off one face and rolls onto another inside one contact: a file that ends
    # while it moves away but the bags still carry > 2 g has not seen the closest approach
    res0 = droptest_result
    smo, st = res0.smoothed, res0.stroke
    n = st.surface.normal
    vn = smo.x[:, rl.SV] @ n
    h = st.smoothed.distance
    i0 = st.contact[0]
    imu = res0.telemetry.imu
    f = np.stack([imu.stack([f"{t}.{a}" for a in "xyz"]) for t in res0.telemetry.triads], axis=1)
    fm = np.interp(smo.t, imu.time - res0.telemetry.group_delay_s, np.linalg.norm(f.mean(axis=1), axis=1))
    # moving away (a first compression over), the stroke above its minimum so far, still > 3 g
    ks = [
        k
        for k in range(i0 + 1, st.max.index)
        if vn[k] > 0.05 and fm[k] > 3.0 * 9.80665 and h[k] > h[i0 : k + 1].min() + 3.0 * st.smoothed.sigma[k]
    ]
    if not ks:
        # on the truth whose pressed bags always push, droptest's drop has one compression (as have 19 of
        # bench_truth_contact.py's 20 validation drops and all of the first 60 tests-stream drops); a file
        # ending mid-contact is the fuzz suite's "IMU ends at 1.45 s": max stroke and restitution undefined
        pytest.skip("this drop has one compression only")
    t_cut = float(smo.t[ks[len(ks) // 2]] + res0.telemetry.group_delay_s)
    paths = _copy(droptest_run, tmp_path)
    _edit_csv(paths["imu"], lambda names, x: x[x[:, 0] <= t_cut])
    s = dt.run_droptest(droptest_run.settings, paths).summary
    assert s["max_stroke"]["distance_m"] is None and "imu.csv" in s["max_stroke"]["undefined"]


# ------------------------------------------------------------------ truth headline


def test_score_headline_inside_3_sigma(droptest_result, droptest_truth):
    sc = dt.score(droptest_result, droptest_truth)
    hl = {h["name"]: h for h in sc["headline"]}
    assert set(hl) == {"max_stroke", "restitution"}
    for h in hl.values():
        assert abs(h["error"]) <= 3.0 * h["sigma"], h
    assert hl["max_stroke"]["error"] == pytest.approx(sc["max_stroke_error_m"])


# ------------------------------------------------------------------ slow: timing, runner end to end


def _user_scenario(settings_path: Path, paths: dict[str, Path], dest: Path) -> Path:
    """The scenario file at ``settings_path`` rewritten as a user-data scenario on ``paths`` (no
    ``[synthetic]`` table, the lander asset path absolute)."""
    from workbench.io.assets import assets_dir

    text = (
        Path(settings_path).read_text(encoding="utf-8").replace('"../landers/', f'"{assets_dir().as_posix()}/landers/')
    )
    text = re.sub(r"\[synthetic\].*?(?=\n\[|\Z)", "", text, flags=re.S)
    table = "[telemetry]\n" + "".join(f'{k} = "{Path(p).as_posix()}"\n' for k, p in paths.items())
    out = dest / "scenario.toml"
    out.write_text(text.replace("[vehicle]", table + "\n[vehicle]", 1), encoding="utf-8")
    return out


@pytest.mark.slow
def test_dead_triad_through_the_runner_is_an_error_verdict_not_a_traceback(droptest_run, tmp_path):
    from workbench.cli import EXIT_UNHEALTHY, main

    paths = _copy(droptest_run, tmp_path / "tel")
    _edit_csv(paths["imu"], _const("PXBP.x", "PXBP.y", "PXBP.z"))
    scen = _user_scenario(droptest_run.settings.path, paths, tmp_path)
    assert main(["run", str(scen), "--out", str(tmp_path / "out"), "-q"]) == EXIT_UNHEALTHY
    # written anyway, the recording draws the run without the dead triad
    assert main(["run", str(scen), "--out", str(tmp_path / "out2"), "-q", "--allow-unhealthy"]) == 0
    assert (tmp_path / "out2" / "droptest.rrd").exists()


@pytest.fixture(scope="module")
def zero_phase_ranging(tmp_path_factory):
    """``droptest_ranging`` telemetry whose IMU went through a zero-phase acquisition filter, and the
    settings that declare it so (the shipped scenario declares the causal Butterworth)."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import load_scenario
    from workbench.problems.droptest.config import DropSettings
    from workbench.problems.droptest.problem import DropTestProblem
    from workbench.problems.droptest.synthetic import synthesize_droptest

    shipped = DropSettings.from_scenario(load_scenario(assets_dir() / "scenarios" / "droptest_ranging.toml"))
    zp = replace(shipped, acquisition=replace(shipped.acquisition, filter="zero_phase"))
    d = tmp_path_factory.mktemp("zp_ranging")
    synthesize_droptest(zp, d, seed=1)
    return shipped, zp, DropTestProblem().telemetry_files(shipped, d)


@pytest.mark.slow
def test_timing_zero_phase_declared_causal_is_an_error_naming_the_key(zero_phase_ranging):
    shipped, zp, paths = zero_phase_ranging
    right = dt.run_droptest(zp, paths).summary
    c = _checks(right["health"], "timing.")["timing.imu_vs_ranging"]
    assert c["status"] == OK, c["message"]
    wrong = dt.run_droptest(shipped, paths).summary
    c = _checks(wrong["health"], "timing.")["timing.imu_vs_ranging"]
    assert c["status"] == ERROR and "[sensors.acquisition] filter = 'butterworth'" in c["message"]
    assert c["value"] == pytest.approx(-wrong["time_shifts_s"]["imu"], abs=3e-4)  # the lag it found: −0.83 ms
    assert wrong["health"]["verdict"] == ERROR
    assert re.search(r"lag [+-][\d.]+ ± 0\.0[5-9]\d ms", c["message"]), c["message"]  # 1σ ≈ 0.07 ms, 3 guns jointly


@pytest.mark.slow
def test_timing_check_names_other_causes_when_the_residuals_are_not_a_time_shift(zero_phase_ranging):
    """A radar gun surveyed with x and y swapped also moves the best lag (1.7 ms, 12σ), but the range
    rates then do not fit a time shift (reduced χ² > 2): the message puts the geometry before the timing."""
    _, zp, paths = zero_phase_ranging
    guns = dict(zp.ranging.radar_guns)
    guns["G1"] = guns["G1"][[1, 0, 2]]
    bad = replace(zp, ranging=replace(zp.ranging, radar_guns=guns))
    c = _checks(dt.run_droptest(bad, paths).summary["health"], "timing.")["timing.imu_vs_ranging"]
    assert c["status"] == ERROR
    assert "do not fit a time shift" in c["message"] and "radar gun position" in c["message"], c["message"]
    chi2 = float(re.search(r"reduced χ² ([\d.]+)", c["message"]).group(1))
    assert chi2 > 2.0


def test_non_finite_filter_state_is_a_numerical_failure_naming_the_stage(droptest_run, droptest_result):
    fwd = droptest_result.forward
    x = fwd.x.copy()
    x[1500:, 0] = np.nan
    bad = replace(fwd, x=x)
    with pytest.raises(np.linalg.LinAlgError, match=r"forward EKF pass: state or covariance not finite from step 1500"):
        dt.finite_or_fail(bad, "forward EKF pass", droptest_run.settings)
    dt.finite_or_fail(fwd, "forward EKF pass", droptest_run.settings)  # finite: nothing raised


def test_restitution_energy_bound():
    """e may exceed 1 only by the energy of rotation (and motion along the surface) the lander brings:
    10 m/s straight in, not spinning, leaving at the same height -> 1; spinning at ω -> √(1 + ωᵀJω/(m v²));
    4 m/s along the surface too -> √(1 + 16/100); rising 0.2 m costs 2 g · 0.2 m of v²."""
    from workbench.problems.droptest.health import restitution_energy_bound

    lander = load_lander(assets_dir() / "landers" / "mer_drop_lander.toml")
    n = np.array([0.0, 0.0, 1.0])

    def bound(v0, w0, dz=0.0):
        x = np.zeros((2, rl.N_X))
        x[0, rl.SV], x[0, rl.SW] = v0, w0
        x[1, rl.SP] = [0.0, 0.0, dz]
        smo = SimpleNamespace(x=x)
        st = SimpleNamespace(restitution_index=(0, 1), surface=SimpleNamespace(normal=n))
        return restitution_energy_bound(smo, st, SimpleNamespace(lander=lander))

    assert bound([0.0, 0.0, -10.0], [0.0, 0.0, 0.0]) == pytest.approx(1.0)
    w = np.array([1.0, -2.0, 0.5])
    spin = w @ lander.inertia_B @ w / lander.mass
    assert bound([0.0, 0.0, -10.0], w) == pytest.approx(np.sqrt(1.0 + spin / 100.0))
    assert bound([4.0, 0.0, -10.0], [0.0, 0.0, 0.0]) == pytest.approx(np.sqrt(1.16))
    assert bound([0.0, 0.0, -10.0], [0.0, 0.0, 0.0], dz=0.2) == pytest.approx(np.sqrt(1.0 - 2 * 9.80665 * 0.2 / 100))
    assert bound([0.0, 0.0, 10.0], [0.0, 0.0, 0.0]) is None  # not approaching: no bound


@pytest.mark.parametrize(("d", "status"), [(-0.08, OK), (-0.12, WARNING), (-0.20, ERROR), (0.03, OK)])
def test_full_stroke_without_rigid_jerk_warns_beyond_2_sigma(monkeypatch, d, status):
    """No rigid jerk in the IMU, the declared geometry's stroke d ± 0.05 m (1σ), no structural give known:
    through the surface by more than 3σ → ERROR, by more than 2σ → WARNING, a grazing miss within 2σ → OK."""
    from workbench.problems.droptest import physics

    monkeypatch.setattr(physics, "rigid_impact", lambda tel: (1500.0, 1.45, 10000.0, 20.0))
    st = SimpleNamespace(max=SimpleNamespace(distance=d, sigma=0.05, time=1.45))
    check = physics.full_stroke_check(None, st, SimpleNamespace(lander_file="lander.toml"), smo=None)
    assert check.status == status, check.message
