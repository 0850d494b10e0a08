"""Defective drop-test telemetry: rejected with a located error, or run with a visible degradation.

Each defect is planted in a COPY of the telemetry the synthetic ``droptest`` run wrote (session
fixture ``droptest_run``). Format defects (NaN, time order, columns, units) must stop the run
with a :class:`TelemetryError` that names file, column and row; sensor defects (dead channel,
saturation, gap) must let the run finish, name the problem in ``summary["degradations"]`` and
keep the max stroke honest (truth inside the reported 3σ).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from workbench.io.telemetry import TelemetryError, read_telemetry, write_telemetry
from workbench.problems.droptest import model as rl
from workbench.problems.droptest import pipeline as dt
from workbench.problems.droptest.telemetry import DropTelemetry, load_drop_telemetry

Rows = list[list[str]]


def _copy_telemetry(run, dst: Path) -> dict[str, Path]:
    """Copy the run's telemetry files (not the truth) into ``dst``; return the pipeline's paths."""
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("imu.csv", "3dm.csv", "events.csv", "setup.toml"):
        shutil.copy(run.telemetry_dir / f, dst / f)
    return run.telemetry_paths(dst)


def _edit_csv(path: Path, fn: Callable[[list[str], Rows], tuple[list[str], Rows]]) -> None:
    """Rewrite a telemetry CSV: ``fn(header_cells, rows_of_cells) -> (header_cells, rows)``;
    metadata lines and every untouched cell are kept byte for byte."""
    lines = path.read_text(encoding="utf-8").splitlines()
    h = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    header, rows = fn(lines[h].split(","), [ln.split(",") for ln in lines[h + 1 :] if ln])
    path.write_text("\n".join([*lines[:h], ",".join(header), *(",".join(r) for r in rows)]) + "\n")


def _load(run, paths: dict[str, Path]) -> DropTelemetry:
    return load_drop_telemetry(run.settings, paths)


def _run(run, paths: dict[str, Path]) -> dt.DropResult:
    return dt.run_droptest(run.settings, paths, seed=run.summary["seed"])


def _error_over_sigma(result: dt.DropResult, truth: dict) -> float:
    return dt.score(result, truth)["max_stroke_error_over_sigma"]


# ------------------------------------------------------------------------------ rejected


def test_nan_in_triad_cell_names_file_column_row(droptest_run, tmp_path):
    paths = _copy_telemetry(droptest_run, tmp_path)
    i = 1234  # 0-based data row -> row 1235 in the error (rows are 1-based under the header)

    def plant(h, rows):
        rows[i][h.index("PXBP.y [g]")] = "nan"
        return h, rows

    _edit_csv(paths["imu"], plant)
    with pytest.raises(TelemetryError) as exc:
        _load(droptest_run, paths)
    err, msg = exc.value, str(exc.value)
    assert err.total == 1
    assert (err.file, err.column, err.row) == (str(paths["imu"]), "PXBP.y [g]", i + 1)
    assert str(paths["imu"]) in msg and "'PXBP.y [g]'" in msg and f"row {i + 1}" in msg
    assert "NaN" in msg


@pytest.mark.parametrize("defect", ["backwards", "duplicate"])
def test_time_order_defect_names_the_row(droptest_run, tmp_path, defect):
    paths = _copy_telemetry(droptest_run, tmp_path)
    i = 2000

    def plant(h, rows):
        rows[i][0] = rows[i - 2][0] if defect == "backwards" else rows[i - 1][0]
        return h, rows

    _edit_csv(paths["imu"], plant)
    with pytest.raises(TelemetryError) as exc:
        _load(droptest_run, paths)
    err, msg = exc.value, str(exc.value)
    assert err.total == 1
    assert (err.column, err.row) == ("time [s]", i + 1)
    assert str(paths["imu"]) in msg and f"row {i + 1}" in msg
    if defect == "backwards":
        assert "time goes backwards" in msg
    else:
        assert "duplicate time" in msg and f"same as row {i}" in msg


def test_missing_column_lists_columns_present(droptest_run, tmp_path):
    paths = _copy_telemetry(droptest_run, tmp_path)

    def drop(h, rows):
        j = h.index("gyro.z [deg/s]")
        return h[:j] + h[j + 1 :], [r[:j] + r[j + 1 :] for r in rows]

    _edit_csv(paths["imu"], drop)
    with pytest.raises(TelemetryError) as exc:
        _load(droptest_run, paths)
    msg = str(exc.value)
    assert "missing column 'gyro.z'" in msg
    assert "columns present: time [s], BP.x [g]," in msg and "gyro.y [deg/s]" in msg
    assert "gyro.z [deg/s]" not in msg


def test_wrong_unit_kind_rejected(droptest_run, tmp_path):
    paths = _copy_telemetry(droptest_run, tmp_path)

    def relabel(h, rows):
        h[h.index("gyro.z [deg/s]")] = "gyro.z [deg]"
        return h, rows

    _edit_csv(paths["imu"], relabel)
    with pytest.raises(TelemetryError) as exc:
        _load(droptest_run, paths)
    err = exc.value
    assert err.column == "gyro.z [deg]"
    assert "has unit of angle, expected angular_rate" in str(err)


# ------------------------------------------------------------------------------ degraded runs


def test_dead_triad_channel_excludes_the_triad_visibly(droptest_run, droptest_result, droptest_truth, tmp_path):
    paths = _copy_telemetry(droptest_run, tmp_path)

    def kill(h, rows):
        j = h.index("MXBP.z [g]")
        for r in rows:
            r[j] = rows[0][j]  # stuck at its first reading for the whole file
        return h, rows

    _edit_csv(paths["imu"], kill)
    res = _run(droptest_run, paths)
    s = res.summary
    errors = [d for d in s["degradations"] if d["level"] == "ERROR"]
    assert len(errors) == 1
    assert "triad MXBP" in errors[0]["text"] and "dead" in errors[0]["text"]
    assert "excluded" in errors[0]["text"]
    assert "MXBP" not in s["innovations"]  # really not used
    assert {"BP", "PYBP", "PXBP"} <= set(s["innovations"])
    # one triad fewer: the reported uncertainty grows, and it still covers the truth
    assert s["max_stroke"]["sigma_m"] > droptest_result.summary["max_stroke"]["sigma_m"]
    assert abs(_error_over_sigma(res, droptest_truth)) <= 3.0


def test_saturated_gyro_burst_is_dropped_with_a_warning(droptest_run, droptest_result, droptest_truth, tmp_path):
    paths = _copy_telemetry(droptest_run, tmp_path)
    t_contact = droptest_result.summary["contact"]["start_s"]
    assert t_contact is not None

    def saturate(h, rows):
        j = h.index("gyro.y [deg/s]")
        i0 = int(np.searchsorted([float(r[0]) for r in rows], t_contact + 0.02))  # inside the impact
        for r in rows[i0 : i0 + 20]:
            r[j] = "1000"  # full scale of the CFX gyro [deg/s]
        return h, rows

    _edit_csv(paths["imu"], saturate)
    res = _run(droptest_run, paths)
    warns = [d for d in res.summary["degradations"] if d["level"] == "WARN"]
    assert len(warns) == 1
    text = warns[0]["text"]
    assert "gyro.y" in text and "20 saturated samples" in text
    assert t_contact <= warns[0]["time_s"] <= t_contact + 0.03
    # 20 samples at 2 kHz leave 9 or 10 whole 1 kHz filter steps without a gyro measurement
    lost = droptest_result.summary["innovations"]["gyro"]["count"] - res.summary["innovations"]["gyro"]["count"]
    assert lost in (9, 10)
    assert abs(_error_over_sigma(res, droptest_truth)) <= 3.0


def test_imu_gap_is_reported_and_covariance_grows(droptest_run, droptest_result, droptest_truth, tmp_path):
    paths = _copy_telemetry(droptest_run, tmp_path)
    kept: list[float] = []

    def cut(h, rows):
        out = [r for r in rows if not 1.0 <= float(r[0]) < 1.03]  # 30 ms before contact (~1.37 s)
        kept.extend(float(r[0]) for r in out)
        return h, out

    _edit_csv(paths["imu"], cut)
    kept_t = np.array(kept)
    t_before = kept_t[kept_t < 1.0].max()
    t_after = kept_t[kept_t >= 1.03].min()

    res = _run(droptest_run, paths)
    s = res.summary
    gaps = [d for d in s["degradations"] if "gap" in d["text"]]
    assert len(gaps) == 1
    assert f"{t_before:.4f}–{t_after:.4f} s" in gaps[0]["text"]
    assert gaps[0]["time_s"] == pytest.approx(t_before, abs=1e-12)
    assert s["steps"] == droptest_result.summary["steps"] - 30  # 30 ms of 1 kHz steps missing

    t = res.smoothed.t
    i = int(np.flatnonzero(np.diff(t) > 0.01)[0])  # last step before the gap
    sig_p = np.sqrt(np.einsum("nii->n", res.smoothed.P[:, rl.EP, rl.EP]))
    assert sig_p[i + 1] > sig_p[i]
    # the growth is the gap's, not only the free fall's: with the same steps' data missing the
    # smoothed σ ends above the clean run's at the same time, and the forward prior of the
    # non-gravitational acceleration is wider than with data
    ref = droptest_result
    j = int(np.searchsorted(ref.smoothed.t, t[i + 1]))
    assert ref.smoothed.t[j] == pytest.approx(t[i + 1], abs=1e-12)
    sig_ref = np.sqrt(np.trace(ref.smoothed.P[j][rl.EP, rl.EP]))
    assert sig_p[i + 1] > sig_ref

    def prior_accel_sigma(r, k):  # the result keeps no priors (memory): the forward pass re-run
        P_prior = dt.forward_pass(droptest_run.settings, r.telemetry, r.initial).forward.P_prior
        return np.sqrt(np.trace(P_prior[k][rl.EA, rl.EA]))

    assert prior_accel_sigma(res, i + 1) > prior_accel_sigma(ref, j)
    assert abs(_error_over_sigma(res, droptest_truth)) <= 3.0


# ------------------------------------------------------------------------------ 3DM scale


def test_non_unit_3dm_vectors_are_normalised(droptest_run, tmp_path):
    """Pinned behaviour: TRIAD uses directions only, so the 3DM means are normalised and a file
    whose vectors are scaled (here ×3) gives the same initial attitude and covariance."""
    paths = _copy_telemetry(droptest_run, tmp_path)
    att = read_telemetry(paths["attitude_3dm"])
    write_telemetry(
        paths["attitude_3dm"],
        att.time,
        {name: (3.0 * att.channel(name), "1") for name in att.names},
        meta=att.meta,
    )
    tel_ref = _load(droptest_run, droptest_run.telemetry_paths())
    tel = _load(droptest_run, paths)
    up = tel.attitude.stack(["up.x", "up.y", "up.z"])
    np.testing.assert_allclose(np.linalg.norm(up, axis=1), 3.0, rtol=1e-6)  # the defect is in
    sc = droptest_run.settings
    a, b = dt.initial_state(sc, tel_ref), dt.initial_state(sc, tel)
    # the file holds 9 significant digits: directions agree to ~1e-9
    for name in ("up_B", "mag_B"):
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=0, atol=1e-8)
    np.testing.assert_allclose(b.q0 * np.sign(b.q0 @ a.q0), a.q0, rtol=0, atol=1e-8)
    np.testing.assert_allclose(b.P_theta, a.P_theta, rtol=1e-6)


# ------------------------------------------------------------------------------ setup / events files


def test_missing_release_event_is_a_located_input_error(droptest_run, tmp_path):
    from workbench.io.scenario import ScenarioError

    paths = _copy_telemetry(droptest_run, tmp_path)
    paths["events"].write_text("time [s],event\n1.2,bungee_cut\n")
    with pytest.raises(ScenarioError) as ei:
        _load(droptest_run, paths)
    assert ei.value.file == str(paths["events"]) and "release" in str(ei.value)


def test_incomplete_setup_names_the_missing_key(droptest_run, tmp_path):
    from workbench.io.scenario import ScenarioError

    paths = _copy_telemetry(droptest_run, tmp_path)
    text = paths["setup"].read_text()
    # the kinematic filter needs the hanging survey (the [bungee] table only in dynamic mode or for an odometer)
    lines = [ln for ln in text.splitlines() if not ln.startswith("position_sigma_m")]
    assert len(lines) < len(text.splitlines())
    paths["setup"].write_text("\n".join(lines) + "\n")
    with pytest.raises(ScenarioError) as ei:
        _load(droptest_run, paths)
    assert ei.value.key == "hanging.position_sigma_m" and str(paths["setup"]) in str(ei.value)


def test_bad_filter_mode_through_the_cli_is_exit_code_3(droptest_run, tmp_path, capsys):
    """A user scenario with a wrong key value: the CLI prints the located error, exit code 3."""
    from workbench.cli import main

    paths = _copy_telemetry(droptest_run, tmp_path / "tel")
    src = droptest_run.scenario.path.read_text()
    body = src.split("[synthetic]")[0].replace('mode = "kinematic"', 'mode = "kinematc"')
    body = body.replace(
        'lander = "../landers/mer_drop_lander.toml"', f'lander = "{droptest_run.scenario.path_of("vehicle.lander")}"'
    )
    tel = "\n".join(f'{k} = "{v}"' for k, v in paths.items())
    user = tmp_path / "user.toml"
    user.write_text(body.replace('name = "droptest"', 'name = "user_drop"') + "\n[telemetry]\n" + tel + "\n")
    assert main(["run", str(user), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "filter.mode" in err and "kinematc" in err and str(user) in err
    assert not list((tmp_path / "out").glob("*.rrd"))  # nothing half-written


def test_3dm_is_averaged_only_while_hanging(droptest_run, tmp_path):
    """3DM rows after release (the lander tumbling) must not enter the initial attitude."""
    paths = _copy_telemetry(droptest_run, tmp_path)
    tel0 = _load(droptest_run, paths)
    init0 = dt.initial_state(droptest_run.settings, tel0)

    def add_tumbling_rows(header, rows):
        extra = [[f"{0.1 + 0.01 * i:.3f}", "1", "0", "0", "0", "1", "0"] for i in range(50)]
        return header, rows + extra

    _edit_csv(paths["attitude_3dm"], add_tumbling_rows)
    init1 = dt.initial_state(droptest_run.settings, _load(droptest_run, paths))
    np.testing.assert_allclose(init1.q0, init0.q0, atol=1e-12)


class _Imu:
    """A stand-in for :class:`~workbench.io.telemetry.Telemetry` with one accelerometer triad whose
    specific-force norm is ``f_g`` [g] along z, at 2 kHz."""

    def __init__(self, t: np.ndarray, f_g: np.ndarray):
        self.time = t
        z = f_g * 9.80665
        self.channels = {"BP.x": 0.0 * z, "BP.y": 0.0 * z, "BP.z": z}

    def stack(self, cols):
        return np.column_stack([self.channels[c] for c in cols])


def _pendulum_drop(cut: float = 1.336) -> _Imu:
    """The profile of the dispersed Monte Carlo drop seed 198: a bungee swing of 0.05–0.95 g until
    the cut, 55 ms of free fall (0.25 g: noise and rotation), the airbag loading the lander
    gradually from 0.5 to 1.6 g over 55 ms, then the impact (8 g) and the rebound (2 g)."""
    t = np.arange(0.0, 2.0, 5e-4)
    f = 0.55 + 0.4 * np.cos(2 * np.pi * t / 1.2)
    free = (t >= cut) & (t < cut + 0.055)
    ramp = (t >= cut + 0.055) & (t < cut + 0.11)
    f[free] = 0.25
    f[ramp] = np.linspace(0.5, 1.6, ramp.sum())
    f[(t >= cut + 0.11) & (t < cut + 0.2)] = 8.0
    f[t >= cut + 0.2] = 2.0
    return _Imu(t, f)


def test_free_fall_check_accepts_a_short_fall_onto_a_soft_airbag():
    """A short free fall followed by a gradual airbag load is a valid drop; before the check looked
    at the early window only, the whole fall's median (0.6 g) failed and the swing's before the cut
    passed for a cut 1000× earlier: the Monte Carlo's seed 198 stopped with "the event times look
    1000× off"."""
    from workbench.problems.droptest.telemetry import check_free_fall

    assert check_free_fall(_pendulum_drop(), {"bungee_cut": 1.336}, ["BP"], "events.csv") == []


def test_free_fall_check_stops_at_the_first_touch_of_the_bags():
    """A cut 16 ms before the bags touch, then a slow load (a vertex first: three bags' corner lobes)
    from 0.3 to 1.9 g over 40 ms before the 2 g sample: free fall up to the touch, no warning; with
    no sample below the touch threshold after the cut the lander never fell freely: a warning."""
    from workbench.problems.droptest.telemetry import check_free_fall

    t = np.arange(0.0, 2.0, 5e-4)
    cut = 1.0
    f = 0.55 + 0.4 * np.cos(2 * np.pi * t / 1.2)
    touch = cut + 0.016
    f[(t >= cut) & (t < touch)] = 0.05
    rise = (t >= touch) & (t < touch + 0.04)
    f[rise] = np.linspace(0.3, 1.9, rise.sum())
    f[t >= touch + 0.04] = 8.0
    assert check_free_fall(_Imu(t, f), {"bungee_cut": cut}, ["BP"], "events.csv") == []
    f[(t >= cut) & (t < touch)] = 0.6
    log = check_free_fall(_Imu(t, f), {"bungee_cut": cut}, ["BP"], "events.csv")
    assert len(log) == 1 and "does not fall freely" in log[0][2]


def test_free_fall_check_names_a_cut_time_in_the_wrong_unit():
    """A cut written 1000× too small (ms values divided twice) lands in the swing: not free fall,
    while 1000× it is — a located error naming the events file and the likely mix-up; a cut that
    is simply wrong is a WARN degradation."""
    from workbench.problems.droptest.telemetry import check_free_fall

    imu = _pendulum_drop()
    with pytest.raises(TelemetryError, match=r"events\.csv.*1000× too small"):
        check_free_fall(imu, {"bungee_cut": 1.336e-3}, ["BP"], "events.csv")
    log = check_free_fall(imu, {"bungee_cut": 0.9}, ["BP"], "events.csv")
    assert len(log) == 1 and log[0][1] == "WARN" and "does not fall freely" in log[0][2]
