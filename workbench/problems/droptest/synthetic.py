"""Synthetic drop test: truth simulation -> telemetry files exactly as a test engineer supplies them.

The truth (``problems.droptest.truth``) is turned into instrument readings (``problems.droptest.sensors``) and
written to CSV/TOML files in the documented user format (``io/FORMATS.md``):

* ``imu.csv`` — the accelerometer triads [g] (``[sensors.accelerometer] triads``) and the rate
  gyro [deg/s] at the IDDAS rate, from a few tenths of a second before release (the lander
  hanging) to the end of the event;
* ``3dm.csv`` — the 3DM gravity and magnetic unit vectors (body frame) while hanging;
* ``events.csv`` — release command and the nail microswitch (bungee cut);
* ``setup.toml`` — surveyed hanging position of the CM (with its 1σ) and the bungee test plan;
* ``ranging.csv`` (if ranging is configured) — bungee-sheave odometer until the cut and radar
  gun ranges / range rates.

The truth is saved beside them in ``truth.npz`` for scoring and drawing only; the
reconstruction (``problems.droptest.pipeline``) reads the telemetry files and never this one.

A scenario run flies the scenario's own fixed, documented drop (``[synthetic]``); the Monte Carlo
flies a different drop per seed, drawn by :func:`disperse_drop` within :class:`DropEnvelope` (the
REDLand test envelope: impact speeds, attitude, bag pressure, timing, true bungee stiffness).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.core.rotation import quat_conjugate, quat_rotate, quat_to_dcm
from workbench.io.telemetry import atomic_write_npz, atomic_write_text, write_events, write_telemetry
from workbench.problems.droptest.config import Accelerometer, Chamber, DropSettings, Gyro, Synthetic
from workbench.problems.droptest.lander import LanderModel
from workbench.problems.droptest.sensors import (
    ImuErrorModel,
    RangingSpec,
    acquisition_filter,
    apply_errors,
    specific_force_at,
    tilt_unit_vectors,
)
from workbench.problems.droptest.surface import Surface, ramp_surface, rock_field
from workbench.problems.droptest.truth import DropTestConfig, DropTruth, mars_from_spf, simulate_drop

__all__ = [
    "SyntheticDrop",
    "DropEnvelope",
    "REDLAND_ENVELOPE",
    "DROP_PARAMETER_NAMES",
    "synthesize_droptest",
    "disperse_drop",
    "drop_config",
    "drop_rng",
    "drop_parameters",
    "PSI",
    "surface_of",
    "truth_for",
    "dispersed_drop",
    "dispersed_settings",
    "dispersed_truth",
    "load_truth",
]


@dataclass(frozen=True)
class SyntheticDrop:
    """Paths written by :func:`synthesize_droptest` (telemetry for the pipeline, truth for scoring)."""

    telemetry: dict[str, Path]
    truth_path: Path


def surface_of(chamber: Chamber) -> Surface:
    """The ramp of the ``[chamber]`` settings (angle [deg], nail depth [m]) in the SPF frame, with
    its rock field if ``chamber.rocks`` is set (seed, extent [[u0, u1], [v0, v1]] in the ramp plane:
    u across, v up-slope, from the foot of the nail; REDLand: 0.2–0.5 m rocks ~1 m apart)."""
    surf = ramp_surface(angle_deg=chamber.ramp_angle_deg, nail_depth=chamber.nail_depth_m)
    if chamber.rocks is not None:
        rk = chamber.rocks
        surf = rock_field(surf, np.random.default_rng(rk.seed), extent=rk.extent_m, spacing=rk.spacing_m)
    return surf


def drop_config(syn: Synthetic) -> DropTestConfig:
    """The scenario's own (fixed, documented) drop: the truth simulator's settings from the
    ``[synthetic]`` settings ``syn`` (bag pressure psi -> Pa)."""
    psi = syn.bag_pressure_psi
    return DropTestConfig(
        impact_parallel_speed=syn.impact_parallel_mps,
        impact_normal_speed=syn.impact_normal_mps,
        release_euler123_deg=tuple(float(a) for a in syn.release_euler123_deg),
        release_to_contact_s=syn.release_to_contact_s,
        pre_release_s=syn.pre_release_s,
        bungee_truth_scale=syn.bungee_truth_scale,
        pressure_pa=None if psi is None else float(psi) * PSI,
    )


#: one pound per square inch [Pa]
PSI = 6894.757


@dataclass(frozen=True)
class DropEnvelope:
    """The test envelope inside which :func:`disperse_drop` draws a drop (uniform draws; SI unless named).

    Source: JPL, REDLand paper on the MER airbag drop tests in the Space Power Facility (c. 2002),
    sections "Test facility" and "Typical test sequence":

    * impact velocity in the Mars frame (ramp level): the worst case the 60° ramp tests is
      "a horizontal velocity of approximately sixteen meters-per-second and a vertical velocity of
      approximately twelve meters-per-second" (vertical from a bridle-release drop from 15 m);
      "a nominal impact would have a minimal horizontal velocity".  Drawn: the speed normal to the
      ramp (Mars vertical) in ``normal_mps`` and along it (Mars horizontal) in ``parallel_mps``,
      the worst case being the upper corner;
    * bag pressure: "the airbags are steadily inflated to the desired bag pressure (1.0 - 1.3 psi)",
      drawn in ``pressure_psi`` (a scenario that sets ``[synthetic] bag_pressure_psi`` outside the
      spec on purpose, the under-inflated full-stroke case, keeps its own pressure);
    * attitude: the series had "down-bag/edge" and "up-bag/edge" drops (section "Results") at a
      configured hanging attitude; the rigging spread is not stated, so roll and pitch are drawn
      within ``tilt_deg`` of the scenario's angles (engineering choice) and the yaw about the body
      +Z axis (the tetrahedron's threefold axis) within ``yaw_deg`` (±60° covers every relative
      orientation of the base triangle);
    * timing: the whole sequence lasts "less than 2.5 seconds" and the bungee is cut about 0.05 s
      before contact.  The bungee can only pull toward the ramp, and the speed along the ramp is
      mostly gained from gravity (``g sin α`` along a ramp of inclination α, the rig's own
      ``[chamber] ramp_angle_deg``), so the time from release to contact cannot exceed about
      ``v_parallel / (g sin α)``; it is drawn as the fraction
      ``contact_time_fraction`` of that time (engineering choice that keeps the bungee design
      feasible: 0.7–0.8 gives 0.8–1.5 s on the 60° ramp);
    * bungee: the count and the stretch are *solved* per drop by the test engineer's energy
      calculation (:func:`~workbench.problems.droptest.truth.design_release`), not drawn; the true
      stiffness relative to the test plan is drawn in ``bungee_truth_scale`` (engineering choice: a
      polynomial fit "accurately modeled" to a few per cent).
    """

    normal_mps: tuple[float, float] = (9.0, 12.0)
    parallel_mps: tuple[float, float] = (10.0, 16.0)
    pressure_psi: tuple[float, float] = (1.0, 1.3)
    tilt_deg: float = 10.0
    yaw_deg: float = 60.0
    contact_time_fraction: tuple[float, float] = (0.70, 0.80)
    bungee_truth_scale: tuple[float, float] = (0.97, 1.06)


#: the envelope used by the Monte Carlo (see :class:`DropEnvelope` for its source)
REDLAND_ENVELOPE = DropEnvelope()

#: names (and units) of :func:`drop_parameters`' entries, in order
DROP_PARAMETER_NAMES: tuple[str, ...] = (
    "impact_normal_target_mps",
    "impact_parallel_target_mps",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
    "bag_pressure_psi",
    "release_to_contact_s",
    "bungee_truth_scale",
    "bungee_count",
    "impact_normal_truth_mps",
    "impact_parallel_truth_mps",
    "release_y_m",
    "release_z_m",
)


def disperse_drop(
    base: DropTestConfig,
    rng: np.random.Generator,
    ramp_angle_deg: float,
    envelope: DropEnvelope = REDLAND_ENVELOPE,
) -> DropTestConfig:
    """Draw one drop of the test envelope around ``base`` (the scenario's drop) for a rig whose
    ramp is inclined ``ramp_angle_deg`` [deg] (``[chamber] ramp_angle_deg``).

    Every draw is uniform, in this order, from ``rng``:

    * ``impact_normal_speed`` [m/s] in ``envelope.normal_mps`` (default 9–12 m/s, target speed
      into the ramp at first contact, Mars-frame vertical);
    * ``impact_parallel_speed`` [m/s] in ``envelope.parallel_mps`` (default 10–16 m/s, down the
      ramp, Mars-frame horizontal);
    * ``release_euler123_deg`` [deg]: roll and pitch = the base's ± ``envelope.tilt_deg`` (10°),
      yaw = the base's ± ``envelope.yaw_deg`` (60°);
    * ``pressure_pa`` [Pa] in ``envelope.pressure_psi`` (1.0–1.3 psi absolute, the test spec),
      unless ``base.pressure_pa`` is set (a scenario's deliberate off-spec pressure is kept);
    * ``release_to_contact_s`` [s] = f · v_parallel / (g sin α), f in
      ``envelope.contact_time_fraction`` (0.70–0.80; α = ``ramp_angle_deg``, the rig's ramp);
    * ``bungee_truth_scale`` [1] in ``envelope.bungee_truth_scale`` (0.97–1.06).

    The release point, bungee count and rope direction follow from these targets by
    :func:`~workbench.problems.droptest.truth.design_release` inside the truth simulation (a
    solved quantity, reported by :func:`drop_parameters`).  Sources and reasons of every range:
    :class:`DropEnvelope`.  Returns a new :class:`DropTestConfig`; ``base`` is unchanged.
    """
    e = envelope
    vn = float(rng.uniform(*e.normal_mps))
    vp = float(rng.uniform(*e.parallel_mps))
    tilt = rng.uniform(-e.tilt_deg, e.tilt_deg, 2)
    yaw = float(rng.uniform(-e.yaw_deg, e.yaw_deg))
    psi = float(rng.uniform(*e.pressure_psi))
    t_c = float(rng.uniform(*e.contact_time_fraction)) * vp / (G0 * np.sin(np.radians(ramp_angle_deg)))
    scale = float(rng.uniform(*e.bungee_truth_scale))
    r0, p0, y0 = (float(a) for a in base.release_euler123_deg)
    return replace(
        base,
        impact_normal_speed=vn,
        impact_parallel_speed=vp,
        release_euler123_deg=(r0 + float(tilt[0]), p0 + float(tilt[1]), y0 + yaw),
        pressure_pa=base.pressure_pa if base.pressure_pa is not None else psi * PSI,
        release_to_contact_s=t_c,
        bungee_truth_scale=scale,
    )


def drop_rng(seed: int) -> np.random.Generator:
    """The generator of drop ``seed``'s draw (:func:`disperse_drop`): a stream of its own,
    ``SeedSequence(seed, spawn_key=(1,))``, independent of the sensor draws (``default_rng(seed)``)."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(1,)))


def drop_parameters(truth: DropTruth, lander: LanderModel, surface: Surface) -> np.ndarray:
    """The drawn and solved parameters of a simulated drop on ``surface``, in
    :data:`DROP_PARAMETER_NAMES` order: target impact speeds [m/s], release attitude (1-2-3) [deg],
    bag pressure [psi], release to contact [s], true bungee scale [1], solved bungee count (test
    plan), the truth's normal and along-ramp CM speeds at first contact [m/s] (in the ramp's Mars
    frame) and the solved release point (SPF y, z) [m]."""
    c = truth.config
    pa = lander.pressure_pa if c.pressure_pa is None else c.pressure_pa
    ev = truth.events
    vn = vp = np.nan
    if "first_contact" in ev:
        v = np.array([np.interp(ev["first_contact"], truth.t, truth.v_I[:, i]) for i in range(3)])
        vm = mars_from_spf(surface) @ v
        vn, vp = float(-vm[2]), float(np.hypot(vm[0], vm[1]))
    return np.array(
        [
            c.impact_normal_speed,
            c.impact_parallel_speed,
            *c.release_euler123_deg,
            pa / PSI,
            c.release_to_contact_s,
            c.bungee_truth_scale,
            truth.nominal_rig.count,
            vn,
            vp,
            truth.p_release[1],
            truth.p_release[2],
        ],
        float,
    )


#: per-process memo of :func:`truth_for` (at most 8 drops; a cache, not a setting)
_TRUTH_CACHE: dict[tuple, DropTruth] = {}


def truth_for(settings: DropSettings, drop: DropTestConfig | None = None) -> tuple[DropTruth, LanderModel, Surface]:
    """Truth simulation of a drop (deterministic; cached per process, keyed by lander file, drop
    configuration and surface including rocks): ``drop`` (default the run's ``[synthetic]`` drop,
    :func:`drop_config`) on the settings' lander and surface."""
    surf = surface_of(settings.chamber)
    lander = settings.lander
    cfg = drop_config(settings.synthetic) if drop is None else drop
    key = (
        str(settings.lander_file),
        cfg,
        surf.point.tobytes(),
        surf.normal.tobytes(),
        surf.rock_centers.tobytes(),
        surf.rock_radii.tobytes(),
    )
    if key not in _TRUTH_CACHE:
        if len(_TRUTH_CACHE) >= 8:
            _TRUTH_CACHE.pop(next(iter(_TRUTH_CACHE)))
        _TRUTH_CACHE[key] = simulate_drop(cfg, lander, surf)
    return _TRUTH_CACHE[key], lander, surf


def dispersed_drop(settings: DropSettings, seed: int, attempts: int = 5) -> DropTestConfig:
    """The drop of Monte Carlo member ``seed``: drawn by :func:`disperse_drop` from :func:`drop_rng`
    ``(seed)`` for the settings' own ramp angle; a draw whose bungee design is infeasible
    (``design_release`` raises inside the truth simulation, which is therefore run here and cached
    by :func:`truth_for`) is redrawn from the same stream, at most ``attempts`` times."""
    rng = drop_rng(seed)
    base = drop_config(settings.synthetic)
    err: ValueError | None = None
    for _ in range(attempts):
        cfg = disperse_drop(base, rng, settings.chamber.ramp_angle_deg)
        try:
            truth_for(settings, cfg)
            return cfg
        except ValueError as exc:  # the test engineer would pick another drop
            err = exc
    raise ValueError(f"{settings.path}: no feasible drop in {attempts} draws for seed {seed}: {err}")


def dispersed_truth(settings: DropSettings, seed: int, attempts: int = 5) -> tuple[DropTruth, LanderModel, Surface]:
    """Truth of Monte Carlo drop ``seed`` (:func:`dispersed_drop`) on the settings' lander and surface."""
    return truth_for(settings, dispersed_drop(settings, seed, attempts))


def dispersed_settings(settings: DropSettings, seed: int) -> DropSettings:
    """The run's settings with its ``[synthetic]`` drop replaced by Monte Carlo drop ``seed``
    (:func:`dispersed_drop`: impact speeds [m/s], release attitude [deg], bag pressure [psi],
    release to contact [s], true bungee scale), so that a plain scenario run
    (:func:`synthesize_droptest` without ``disperse``) flies it; sensors, rig, rocks and the survey
    σ are the scenario's.  The health calibration's members (``calibration_settings``)."""
    cfg = dispersed_drop(settings, seed)
    syn = replace(
        settings.synthetic,
        impact_parallel_mps=cfg.impact_parallel_speed,
        impact_normal_mps=cfg.impact_normal_speed,
        release_euler123_deg=tuple(float(a) for a in cfg.release_euler123_deg),
        release_to_contact_s=cfg.release_to_contact_s,
        bungee_truth_scale=cfg.bungee_truth_scale,
        bag_pressure_psi=None if cfg.pressure_pa is None else float(cfg.pressure_pa) / PSI,
    )
    out = replace(settings, synthetic=syn)
    truth_for(out)  # the drop as the run will fly it (psi -> Pa may round by an ulp): simulated once, cached
    return out


def _imu_models(acc: Accelerometer, gyro: Gyro) -> tuple[ImuErrorModel, ImuErrorModel]:
    """The accelerometer and gyro error models (SI) of the sensor settings."""
    acc_model = ImuErrorModel(
        noise=acc.noise_g * G0,
        bias=acc.bias_g * G0,
        scale=acc.scale,
        misalignment=np.radians(acc.misalignment_deg),
        full_scale=acc.full_scale_g * G0,
    )
    gyr_model = ImuErrorModel(
        noise=np.radians(gyro.noise_dps),
        bias=np.radians(gyro.bias_dps),
        scale=gyro.scale,
        misalignment=np.radians(gyro.misalignment_deg),
        full_scale=np.radians(gyro.full_scale_dps),
    )
    return acc_model, gyr_model


def synthesize_droptest(
    settings: DropSettings,
    out_dir: str | Path,
    seed: int | None = None,
    disperse: bool = False,
    *,
    compress_truth: bool = True,
) -> SyntheticDrop:
    """Simulate a drop of the run with ``settings`` and write its telemetry files into ``out_dir``.

    ``seed`` (default ``[synthetic] seed``) drives every sensor-side draw through
    ``default_rng(seed)``: sensor noise, bias, scale factor and misalignment, 3DM vector errors,
    the survey error of the hanging position and the ranging noise.  With ``disperse=False`` (a
    scenario run) the drop is the scenario's own fixed, documented drop; with ``disperse=True`` (the
    Monte Carlo) the drop itself is drawn by :func:`disperse_drop` from :func:`drop_rng` ``(seed)``,
    so every seed is a different drop.  The drawn parameters are saved in ``truth.npz``
    (``drop_parameters``, ``drop_parameter_names``); ``compress_truth=False`` writes it uncompressed
    (the same arrays; a Monte Carlo member deletes it right after scoring).
    """
    cfg = settings
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed = int(cfg.synthetic.seed if seed is None else seed)
    rng = np.random.default_rng(seed)
    if disperse:
        truth, lander, surf = dispersed_truth(settings, seed)
    else:
        truth, lander, surf = truth_for(settings)
    acc_model, gyr_model = _imu_models(cfg.accelerometer, cfg.gyro)
    fs_sim = truth.config.output_rate_hz
    aq = cfg.acquisition
    fs, cutoff, order, kind = aq.sample_rate_hz, aq.cutoff_hz, aq.order, aq.filter
    decim = int(round(fs_sim / fs))
    if abs(decim * fs - fs_sim) > 1e-6:
        raise ValueError(f"{settings.path}: sensors.acquisition.sample_rate_hz must divide {fs_sim} Hz")

    t_imu = truth.t[::decim]
    channels: dict[str, tuple[np.ndarray, str]] = {}
    drawn: dict[str, dict] = {}
    triads = cfg.accelerometer.triads  # the scenario's triads, each at its lever arm in the asset
    for name in triads:
        r = lander.instruments[name]
        f_true = specific_force_at(r, truth.a_ng_I, truth.q_I_B, truth.w_B, truth.alpha_B)
        f_filt = acquisition_filter(f_true, fs_sim, cutoff, order, kind)[::decim]
        f_meas, drawn[name] = apply_errors(f_filt, acc_model, rng)
        for i, ax in enumerate("xyz"):
            channels[f"{name}.{ax}"] = (f_meas[:, i], "g")
    w_filt = acquisition_filter(truth.w_B, fs_sim, cutoff, order, kind)[::decim]
    w_meas, drawn["gyro"] = apply_errors(w_filt, gyr_model, rng)
    for i, ax in enumerate("xyz"):
        channels[f"gyro.{ax}"] = (w_meas[:, i], "deg/s")
    paths = {
        "imu": write_telemetry(
            out / "imu.csv",
            t_imu,
            channels,
            meta={
                "sensor": "IDDAS: 4 accelerometer triads (ENDEVCO 7264) + CFX rate gyro",
                "rate_hz": fs,
                "source": f"synthetic drop, seed {seed}",
                "acquisition_filter": (
                    f"Butterworth order {order}, {cutoff:g} Hz" + (", zero-phase" if kind == "zero_phase" else "")
                    if kind != "none"
                    else "none"
                ),
            },
        )
    }

    # 3DM while hanging: gravity (accelerometer set measures -g => "up") and magnetic field
    m_spf = cfg.chamber.magnetic_field_spf  # required, as in the reconstruction
    m_spf = m_spf / np.linalg.norm(m_spf)
    sg = np.radians(cfg.attitude_3dm.gravity_sigma_deg)
    sm = np.radians(cfg.attitude_3dm.magnetic_sigma_deg)
    rate3 = cfg.attitude_3dm.rate_hz
    n3 = max(2, int(truth.config.pre_release_s * rate3 * 0.8))
    t3 = -truth.config.pre_release_s + np.arange(n3) / rate3
    q_B_I = quat_conjugate(truth.q_release)
    up_B = quat_rotate(q_B_I, np.array([0.0, 0.0, 1.0]))
    mag_B = quat_rotate(q_B_I, m_spf)
    # a per-run calibration error (the dominant term) plus small per-sample noise
    up_cal = tilt_unit_vectors(up_B, sg, rng)
    mag_cal = tilt_unit_vectors(mag_B, sm, rng)
    up_s = tilt_unit_vectors(up_cal, 0.1 * sg, rng, n3)
    mag_s = tilt_unit_vectors(mag_cal, 0.1 * sm, rng, n3)
    ch3 = {f"up.{a}": (up_s[:, i], "1") for i, a in enumerate("xyz")}
    ch3.update({f"mag.{a}": (mag_s[:, i], "1") for i, a in enumerate("xyz")})
    paths["attitude_3dm"] = write_telemetry(
        out / "3dm.csv",
        t3,
        ch3,
        meta={
            "sensor": "Microstrain 3DM: unit vectors of specific force (up) and magnetic field, body frame",
            "rate_hz": rate3,
        },
    )

    # events: release command and the nail microswitch
    ev = [(0.0, "release")]
    if "bungee_cut" in truth.events:
        ev.append((round(truth.events["bungee_cut"] / (1.0 / fs)) * (1.0 / fs), "bungee_cut"))
    paths["events"] = write_events(out / "events.csv", ev)

    # setup: surveyed hanging position and the bungee test plan
    sig_survey = cfg.synthetic.survey_sigma_m
    p_survey = truth.p_release + rng.normal(0.0, sig_survey, 3)
    rig = truth.nominal_rig
    fmt = lambda v: "[" + ", ".join(f"{float(x):.6f}" for x in v) + "]"  # noqa: E731
    setup = (
        "# Drop-test setup: surveyed hanging state and the bungee test plan (SPF frame, SI units)\n"
        "[hanging]\n"
        f"position_m = {fmt(p_survey)}\n"
        f"position_sigma_m = {sig_survey}\n"
        "[bungee]\n"
        f"anchor_m = {fmt(rig.anchor_I)}\n"
        f"rest_length_m = {rig.rest_length:.6f}\n"
        f"coefficients = {fmt(rig.coeffs)}  # N/m^k per bungee, k = 1..\n"
        f"count = {rig.count:.6f}\n"
        f"attach_body_m = {fmt(rig.attach_B + lander.cm_L)}  # lander frame\n"
        f"mass_kg = {lander.mass}\n"
    )
    if surf.n_rocks:  # the surveyed rock field (rigid spheres: centre in SPF, radius)
        setup += "[rocks]\n# surveyed rock field on the ramp: sphere centres (SPF) and radii\n"
        setup += "centers_m = [" + ", ".join(fmt(c) for c in surf.rock_centers) + "]\n"
        setup += f"radii_m = {fmt(surf.rock_radii)}\n"
    paths["setup"] = atomic_write_text(out / "setup.toml", setup)

    if cfg.ranging.enabled:
        paths["ranging"] = _write_ranging(RangingSpec.from_settings(cfg.ranging), truth, out, rng, lander)

    truth_path = out / "truth.npz"
    atomic_write_npz(
        truth_path,
        dict(
            t=truth.t,
            p_I=truth.p_I,
            v_I=truth.v_I,
            q_I_B=truth.q_I_B,
            w_B=truth.w_B,
            alpha_B=truth.alpha_B,
            a_ng_I=truth.a_ng_I,
            contact_force=truth.contact_force,
            gauge_pressure=truth.gauge_pressure,
            body_penetration=truth.body_penetration,
            event_names=np.array(list(truth.events)),
            event_times=np.array(list(truth.events.values())),
            accel_bias=np.array([drawn[n]["bias"] for n in triads]),
            gyro_bias=drawn["gyro"]["bias"],
            gyro_scale=drawn["gyro"]["scale"],
            gyro_error_matrix=drawn["gyro"]["matrix"],
            seed=seed,
            drop_parameters=drop_parameters(truth, lander, surf),
            drop_parameter_names=np.array(DROP_PARAMETER_NAMES),
            dispersed=disperse,
        ),
        compress=compress_truth,
    )
    return SyntheticDrop(telemetry=paths, truth_path=truth_path)


def _write_ranging(
    spec: RangingSpec, truth: DropTruth, out: Path, rng: np.random.Generator, lander: LanderModel
) -> Path:
    """Write ``ranging.csv`` of the instruments ``spec`` along ``truth`` (noise from ``rng``)."""
    step = int(round(truth.config.output_rate_hz / spec.rate_hz))
    idx = np.arange(0, truth.t.size, step)
    t = truth.t[idx]
    p, v, q, w = truth.p_I[idx], truth.v_I[idx], truth.q_I_B[idx], truth.w_B[idx]
    C = quat_to_dcm(q)
    ch: dict[str, tuple[np.ndarray, str]] = {}
    sparse = []
    if spec.odometer:
        x_att = p + C @ truth.rig.attach_B
        rho = np.linalg.norm(truth.rig.anchor_I - x_att, axis=1) + rng.normal(0.0, spec.odometer_sigma, t.size)
        rho = rho - spec.odometer_zero  # the odometer counts from its own zero
        if spec.odometer_quantisation > 0.0:  # a whole number of count steps
            rho = spec.odometer_quantisation * np.round(rho / spec.odometer_quantisation)
        cut = truth.events.get("bungee_cut", np.inf)
        rho = np.where((t >= 0.0) & (t < cut), rho, np.nan)  # the sheave turns only while towing
        ch["odometer"] = (rho, "m")
        sparse.append("odometer")
    for name, G in spec.guns.items():
        r_B = lander.to_body(spec.reflectors_L[name])
        d = p + C @ r_B - G
        rho = np.linalg.norm(d, axis=1)
        u = d / rho[:, None]
        vr = v + np.einsum("nij,nj->ni", C, np.cross(w, r_B))
        ch[f"{name}.range"] = (rho + rng.normal(0.0, spec.range_sigmas[name], t.size), "m")
        ch[f"{name}.rate"] = (np.sum(u * vr, axis=1) + rng.normal(0.0, spec.rate_sigmas[name], t.size), "m/s")
    return write_telemetry(
        out / "ranging.csv",
        t,
        ch,
        sparse=tuple(sparse),
        meta={"sensor": "bungee-sheave odometer and radar guns", "rate_hz": spec.rate_hz},
    )


def load_truth(path: str | Path) -> dict[str, np.ndarray]:
    """Load ``truth.npz`` written by :func:`synthesize_droptest` (scoring and drawing only)."""
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    d["events"] = {str(k): float(v) for k, v in zip(d.pop("event_names"), d.pop("event_times"), strict=True)}
    return d
