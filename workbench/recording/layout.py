"""Entity paths and timeline names of a workbench recording (documented in ``docs/RECORDING.md``).

Every recorder and the reader name entities through this module, so the layout lives in one place:
no recorder spells a path itself. Paths are absolute Rerun entity paths (leading ``/``). The names
are grouped:

* generic paths every problem shares (``WORLD``, ``VEHICLE``, ``PLOTS``, ``REPORT`` ...);
* ``DROPTEST_*``: the drop-test reconstruction (``workbench.problems.droptest.recording``);
* ``ENTRY_*``: the entry and descent reconstruction (``workbench.problems.entry.recording``);
* ``MC_*``: the drop-test Monte Carlo (``workbench.problems.droptest.recording_mc``);
* ``VALIDATION_*``: the entry smoother validation (``workbench.problems.entry.recording_mc``);
* leaf names (``VALUE``, ``TRUTH_SERIES``, ``FORWARD_SERIES`` ...) of series under a plot root;
* families of paths with a caller-given part (a sensor, an axis, a beam) as small functions, e.g.
  :func:`residual_path`; :func:`path_families` lists their templates.

:func:`constant_paths` lists every constant path; ``tests/recording/test_layout.py`` checks that
each one, and each family template, is documented in ``docs/RECORDING.md`` and vice versa.

Names of path parts given by callers (quantities, sensors, channels) must be plain words: letters,
digits, ``_``, ``-`` and ``.``; a ``/`` inside a part nests (``"velocity/north"`` →
``/plots/velocity/north``).

Timelines:

* ``time`` (duration): float seconds from the scenario's reference event (release, entry interface),
  stored as integer nanoseconds;
* ``step`` (sequence): filter sample index;
* ``iteration`` (sequence): iteration of an iterative solver (Gauss-Newton, drag-coefficient loop);
* ``sample`` (sequence): Monte Carlo member.

This module does not import rerun; it is plain strings.
"""

from __future__ import annotations

import re

APPLICATION_ID = "edl-workbench"
"""Application id of every recording; a blueprint only applies to recordings with the same id."""

# ---------------------------------------------------------------------------------------- timelines
TIME = "time"
STEP = "step"
ITERATION = "iteration"
SAMPLE = "sample"
#: A flight condition as the x axis: the value is −round(100 · Mach), so Mach decreases left to
#: right as in flight (−2500 = Mach 25); Rerun plots against timelines only, and they are integers.
MACH_DESCENDING = "minus_100_mach"
TIMELINES = (TIME, STEP, ITERATION, SAMPLE, MACH_DESCENDING)

# ------------------------------------------------------------------------------- generic: 3D scene
WORLD = "/world"
SURFACE = "/world/surface"
VEHICLE = "/world/vehicle"
VEHICLE_BODY = "/world/vehicle/body"
AIRBAGS = "/world/vehicle/airbags"
RADAR = "/world/vehicle/radar"
UNCERTAINTY = "/world/vehicle/uncertainty"
VEHICLE_MARKER = "/world/vehicle/marker"
ESTIMATE = "/world/estimate"
ESTIMATE_FORWARD = "/world/estimate/forward"
ESTIMATE_SMOOTHED = "/world/estimate/smoothed"
TRUTH = "/world/truth"
TRUTH_VEHICLE = "/world/truth/vehicle"
STROKE = "/world/stroke"
DISPERSION = "/world/dispersion"

# --------------------------------------------------------------------------- generic: plots, text
PLOTS = "/plots"
RESIDUALS = "/residuals"
SENSORS = "/sensors"
PROFILES = "/profiles"
EVENTS = "/events"
#: Bookmarks of the run's key moments (TextLog, one row per moment; ``recording.moments``).
KEY_MOMENTS = "/events/key_moments"
REPORT = "/report"
#: What each track and body of the 3D scene is (markdown TextDocument beside the 3D views).
SCENE_KEY = "/report/scene_key"
#: The health verdict of the reconstruction (markdown TextDocument, ``estimation.health``).
HEALTH = "/report/health"

# ------------------------------------------------- leaf names of the series under a plot root
VALUE = "value"
TRUTH_SERIES = "truth"
FORWARD_SERIES = "forward"
SMOOTHED_SERIES = "smoothed"
MEASURED_SERIES = "measured"
PREDICTED_SERIES = "predicted"
RAW_SERIES = "raw"
DEFAULT_SERIES = "default"
BLACKOUT_FILL_SERIES = "blackout_fill"
ITERATION_SERIES = "iteration"
GRID = "grid"
LABELS = "labels"
LEGEND = "legend"
ACCEPTED = "accepted"
REJECTED = "rejected"

# ----------------------------------------------------------------------------------- drop test
DROPTEST_CHAMBER_AXES = "/world/chamber"
DROPTEST_ROCKS = "/world/surface/rocks"
DROPTEST_TRIADS = "/world/vehicle/triads"
DROPTEST_STROKE_LABEL = "/world/stroke/label"
DROPTEST_ROLL_LINE = "/world/roll_line"
DROPTEST_MAX_STROKE = "/world/max_stroke"
DROPTEST_MAX_STROKE_BODY = "/world/max_stroke/body"
DROPTEST_MAX_STROKE_AIRBAGS = "/world/max_stroke/airbags"
DROPTEST_MAX_STROKE_SEGMENT = "/world/max_stroke_segment"
DROPTEST_MAX_STROKE_POINT = "/world/max_stroke_point"
DROPTEST_MAX_STROKE_DIMENSION = "/world/max_stroke_dimension"
DROPTEST_MAX_STROKE_DIMENSION_LABEL = "/world/max_stroke_dimension/label"
DROPTEST_TRUTH_BODY = "/world/truth/vehicle/body"
DROPTEST_TRUTH_TRAJECTORY = "/world/truth/trajectory"
DROPTEST_SENSOR_GYRO = "/sensors/gyro"
DROPTEST_SENSOR_RANGING = "/sensors/ranging"
DROPTEST_PLOT_STROKE = "/plots/stroke"
DROPTEST_PLOT_STROKE_SIGMA = "/plots/stroke_sigma"
DROPTEST_PLOT_POSITION = "/plots/position"
DROPTEST_PLOT_VELOCITY = "/plots/velocity"
DROPTEST_PLOT_ACCEL_BODY = "/plots/accel_body"
DROPTEST_PLOT_ACCEL_SPF = "/plots/accel_spf"
DROPTEST_PLOT_RATE = "/plots/rate"
DROPTEST_PLOT_ANGULAR_ACCEL = "/plots/angular_accel"
DROPTEST_PLOT_QUATERNION = "/plots/quaternion"
DROPTEST_PLOT_EULER123 = "/plots/euler123"
DROPTEST_PLOT_SIGMA = "/plots/sigma"
DROPTEST_PLOT_GYRO_SCALE = "/plots/gyro_scale"
DROPTEST_PLOT_TRIADS = "/plots/triads"
DROPTEST_PLOT_NIS = "/plots/nis"
DROPTEST_PLOT_PROCESS_NOISE = "/plots/process_noise"

# ------------------------------------------------------------------------------ entry and descent
ENTRY_SITE_AXES = "/world/site_axes"
ENTRY_BACK_SHELL = "/world/vehicle/body/back_shell"
ENTRY_FRONT_SHIELD = "/world/vehicle/body/front_shield"
ENTRY_BODY_AXES = "/world/vehicle/body/axes"
ENTRY_PARACHUTE = "/world/vehicle/body/parachute"
ENTRY_RISERS = "/world/vehicle/body/risers"
ENTRY_ONBOARD_TRACK = "/world/onboard/track"
ENTRY_NOMINAL_TRACK = "/world/estimate/nominal"
ENTRY_GROUND_TRACK = "/world/estimate/ground_track"
ENTRY_FORWARD_VEHICLE = "/world/estimate/forward_vehicle"
ENTRY_FORWARD_UNCERTAINTY = "/world/estimate/forward_vehicle/uncertainty"
ENTRY_UNCERTAINTY_LABEL = "/world/vehicle/uncertainty_label"
ENTRY_UNCERTAINTY_SIGMA_LABEL = "/world/vehicle/uncertainty/sigma_label"
ENTRY_FORWARD_SIGMA_LABEL = "/world/estimate/forward_vehicle/uncertainty/sigma_label"
ENTRY_TRUTH_TRACK = "/world/truth/track"
ENTRY_TRUTH_GROUND_TRACK = "/world/truth/ground_track"
ENTRY_TRUTH_VEHICLE_AXES = "/world/truth/vehicle/axes"
ENTRY_TRUTH_PARACHUTE = "/world/truth/parachute"
ENTRY_SENSOR_GNC_RATE = "/sensors/gnc/rate"
ENTRY_SENSOR_GNC_ACCEL = "/sensors/gnc/accel_total_M"
ENTRY_SENSOR_RDA_SLANT_OUT = "/sensors/rda/slant_out"
ENTRY_SENSOR_RDA_V_OUT = "/sensors/rda/v_out_G"
ENTRY_SENSOR_RDA_SLANT_RANGE = "/sensors/rda/slant_range"
ENTRY_PLOT_ALTITUDE_AGL = "/plots/altitude_agl"
ENTRY_PLOT_ALTITUDE_AGL_PLANE_FIT = "/plots/altitude_agl/plane_fit"
ENTRY_PLOT_ALTITUDE_AMR = "/plots/altitude_amr"
ENTRY_PLOT_VELOCITY_NED = "/plots/velocity_ned"
ENTRY_PLOT_TILT = "/plots/tilt"
ENTRY_PLOT_SIGMA_POSITION = "/plots/sigma_position"
ENTRY_PLOT_SIGMA_POSITION_NORM = "/plots/sigma_position/norm"
ENTRY_PLOT_ALTITUDE_3SIGMA_SMOOTHED = "/plots/sigma_position/altitude_3sigma_smoothed"
ENTRY_PLOT_ALTITUDE_3SIGMA_FORWARD = "/plots/sigma_position/altitude_3sigma_forward"
ENTRY_PLOT_SIGMA_VELOCITY = "/plots/sigma_velocity"
ENTRY_PLOT_SIGMA_ATTITUDE = "/plots/sigma_attitude"
ENTRY_PLOT_ERROR = "/plots/error"
ENTRY_PLOT_ERROR_ALTITUDE = "/plots/error/altitude"
ENTRY_PLOT_STRAPDOWN = "/plots/strapdown"
ENTRY_PLOT_STRAPDOWN_H_AMR = "/plots/strapdown/h_amr"
ENTRY_PLOT_ONBOARD = "/plots/onboard"
ENTRY_PLOT_ONBOARD_POSITION_DIFF = "/plots/onboard/position_diff"
ENTRY_PLOT_ONBOARD_ATTITUDE_DIFF = "/plots/onboard/attitude_diff_deg"
ENTRY_PLOT_IMU_F = "/plots/imu/f_G"
ENTRY_PLOT_IMU_F_RESAMPLED = "/plots/imu/f_G/resampled_100Hz_z"
ENTRY_PLOT_IMU_W = "/plots/imu/w_G"
ENTRY_PLOT_IMU_W_REBUILT = "/plots/imu/w_G/rebuilt_x"
ENTRY_PLOT_ATMOSPHERE = "/plots/atmosphere"
ENTRY_PLOT_ATMOSPHERE_MAX_REL_CHANGE = "/plots/atmosphere/max_rel_change"
ENTRY_PLOT_DENSITY_RATIO = "/plots/atmosphere/density_ratio_pct"
ENTRY_PLOT_DENSITY_RATIO_TRUTH = "/plots/atmosphere/density_ratio_pct_truth"
ENTRY_PLOT_WIND = "/plots/wind"
ENTRY_PLOT_DISPERSION = "/plots/dispersion"
ENTRY_PLOT_RADAR = "/plots/radar"
ENTRY_RESIDUALS_RDA = "/residuals/rda"
ENTRY_RESIDUAL_SLANT_OUT = "/residuals/rda/slant_out"
ENTRY_RESIDUAL_VELOCITY_OUT = "/residuals/rda/velocity_out"
ENTRY_RESIDUAL_SLANT_RANGE = "/residuals/rda/slant_range"
ENTRY_PROFILE_DENSITY = "/profiles/density"
ENTRY_PROFILE_PRESSURE = "/profiles/pressure"
ENTRY_PROFILE_TEMPERATURE = "/profiles/temperature"
ENTRY_PROFILE_WIND = "/profiles/wind"

# ---------------------------------------------------------------------- flush air data (MEADS)
MEADS_HEAT_SHIELD = "/world/vehicle/heat_shield"
MEADS_PORTS = "/world/vehicle/heat_shield/ports"
MEADS_PORT_RESIDUALS = "/world/vehicle/heat_shield/port_residuals"
MEADS_PORT_LABELS = "/world/vehicle/heat_shield/port_labels"
MEADS_PORT_LEADERS = "/world/vehicle/heat_shield/port_leaders"
MEADS_AIR_VELOCITY = "/world/vehicle/air_velocity"
MEADS_PLOT_PORTS = "/plots/ports"
MEADS_TRADE_STUDY = "/plots/trade_study"
MEADS_TRUTH_MC = "/plots/truth_mc"
#: post2 Monte Carlo against the truth (``workbench mc post2_huygens --truth-sim``)
POST2_TRUTH_MC = "/plots/post2_truth_mc"
MEADS_PLOT_SCALE_FACTORS = "/plots/scale_factors"
# ------------------------------------------------------------------ post2 (problem-file reconstruction)
POST2_FOREBODY = "/world/vehicle/body/forebody"
POST2_BACK_SHELL = "/world/vehicle/body/backshell"
POST2_PARACHUTE = "/world/vehicle/parachute"
POST2_RISERS = "/world/vehicle/parachute_risers"
#: the local horizontal plane under the vehicle (grid + north/east marks), rotated into the vehicle
#: frame each step, so the Vehicle view (origin at the vehicle) shows the attitude against it
POST2_HORIZON = "/world/vehicle/horizon"
#: the planet-relative velocity direction at the vehicle (arrow, vehicle frame)
POST2_VELOCITY_ARROW = "/world/vehicle/velocity"
POST2_PHASE = "/plots/phase"
#: a rocket flight's track in the pad's frame (``[launch]``; ``problems/post2/rocket_results.py``)
POST2_ROCKET = "/plots/rocket"
POST2_ROCKET_ALTITUDE = "/plots/rocket/altitude_above_pad"
POST2_ROCKET_VERTICAL_SPEED = "/plots/rocket/vertical_speed"
POST2_ROCKET_SPEED = "/plots/rocket/speed"
POST2_ROCKET_DOWNRANGE = "/plots/rocket/downrange"
POST2_ROCKET_EAST = "/plots/rocket/east"
POST2_ROCKET_NORTH = "/plots/rocket/north"
POST2_ROCKET_UP = "/plots/rocket/up"
#: the rocket's plots in the order a reviewer reads them (the summary image's panels)
POST2_ROCKET_PLOTS = (
    POST2_ROCKET_ALTITUDE,
    POST2_ROCKET_VERTICAL_SPEED,
    POST2_ROCKET_SPEED,
    POST2_ROCKET_DOWNRANGE,
    POST2_ROCKET_EAST,
    POST2_ROCKET_NORTH,
)

# ------------------------------------------------------------------------- drop-test Monte Carlo
MC_ROOT = "/plots/mc"
MC_STROKE = "/plots/mc/stroke"
MC_STROKE_ERROR = "/plots/mc/stroke/error"
MC_STROKE_PLUS_3SIGMA = "/plots/mc/stroke/plus_3sigma"
MC_STROKE_MINUS_3SIGMA = "/plots/mc/stroke/minus_3sigma"
MC_NEES = "/plots/mc/nees"
MC_NEES_STROKE = "/plots/mc/nees/stroke"
MC_NEES_POSE_AT_MAX = "/plots/mc/nees/pose_at_max"
MC_RESTITUTION = "/plots/mc/restitution"
MC_RESTITUTION_ERROR = "/plots/mc/restitution/error"

# ------------------------------------------------------------------ entry smoother validation
VALIDATION_ROOT = "/plots/validation"
VALIDATION_ANEES = "/plots/validation/anees"
VALIDATION_ANEES_SMOOTHED = "/plots/validation/anees/smoothed"
VALIDATION_ANEES_SMOOTHED_CURVILINEAR = "/plots/validation/anees/smoothed_curvilinear"
VALIDATION_ANEES_FORWARD = "/plots/validation/anees/forward"
VALIDATION_ANEES_FORWARD_CURVILINEAR = "/plots/validation/anees/forward_curvilinear"
VALIDATION_ANEES_BAND_LO = "/plots/validation/anees/band_lo"
VALIDATION_ANEES_BAND_HI = "/plots/validation/anees/band_hi"
VALIDATION_RMS = "/plots/validation/rms"
VALIDATION_RMS_POSITION = "/plots/validation/rms/position"
VALIDATION_RMS_ALTITUDE = "/plots/validation/rms/altitude"
VALIDATION_RMS_VELOCITY = "/plots/validation/rms/velocity"
VALIDATION_RMS_ATTITUDE = "/plots/validation/rms/attitude"
VALIDATION_RMS_GROUPS = (
    VALIDATION_RMS_POSITION,
    VALIDATION_RMS_ALTITUDE,
    VALIDATION_RMS_VELOCITY,
    VALIDATION_RMS_ATTITUDE,
)
VALIDATION_RUNS = "/plots/validation/runs"
VALIDATION_RUNS_NEES = "/plots/validation/runs/nees"
VALIDATION_RUNS_NEES_TIME_AVG = "/plots/validation/runs/nees/time_avg"
VALIDATION_RUNS_NEES_CURVILINEAR = "/plots/validation/runs/nees/curvilinear"
VALIDATION_RUNS_INSIDE_3SIGMA_X9 = "/plots/validation/runs/nees/inside_3sigma_x9"
VALIDATION_RUNS_H_AGL = "/plots/validation/runs/h_agl"
VALIDATION_RUNS_H_AGL_ERROR_MAX = "/plots/validation/runs/h_agl/error_max"
VALIDATION_RUNS_H_AGL_THREE_SIGMA = "/plots/validation/runs/h_agl/three_sigma"

# ------------------------------------------- comparison of two runs (``workbench compare``)
COMPARE_ROOT = "/compare"
COMPARE_DIFF = "/compare/diff"
COMPARE_OVERLAY = "/compare/overlay"
COMPARE_POSITION = "/compare/position"
COMPARE_POSITION_NORM = "/compare/position/norm"
COMPARE_REPORT_A = "/compare/report_a"
COMPARE_REPORT_B = "/compare/report_b"
COMPARE_CHANGES = "/compare/changes"
COMPARE_RUNS = ("a", "b")

_PART = re.compile(r"^[\w.\-]+$")


def part(name: str) -> str:
    """Check one entity-path part (no ``/``) and return it; raise ``ValueError`` if it needs escaping."""
    if not isinstance(name, str) or not _PART.match(name):
        raise ValueError(f"entity path part {name!r} must be non-empty letters, digits, '_', '-' or '.'")
    return name


def join(root: str, *parts: str) -> str:
    """Join ``root`` (an absolute path) and checked parts; each part may contain ``/`` to nest."""
    out = root.rstrip("/")
    for p in parts:
        for q in str(p).split("/"):
            out += "/" + part(q)
    return out


def bound_names(nsigma: float = 3.0) -> tuple[str, str]:
    """Leaf names of the upper and lower bound series, e.g. ``("plus_3sigma", "minus_3sigma")``."""
    return f"plus_{nsigma:g}sigma", f"minus_{nsigma:g}sigma"


def subtree(path: str) -> str:
    """``<path>/**``: the blueprint query matching ``path`` and every entity below it."""
    return path.rstrip("/") + "/**"


# ------------------------------------------------------------------------- generic path families
def radar_beam_path(beam: int | str) -> str:
    """``/world/vehicle/radar/B<beam>`` for an integer beam index, or ``/world/vehicle/radar/<beam>``."""
    return join(RADAR, f"B{beam}" if isinstance(beam, int) else beam)


def truth_path(sub: str) -> str:
    """``/world/truth/<sub>``: the truth counterpart of a scene entity (synthetic scenarios only)."""
    return join(TRUTH, sub)


def plot_path(quantity: str) -> str:
    """``/plots/<quantity>``: root of one plotted quantity (children value, plus_3sigma, ...)."""
    return join(PLOTS, quantity)


def residual_path(sensor: str, channel: str | None = None) -> str:
    """``/residuals/<sensor>[/<channel>]``: root of one measurement residual (children ``value`` and
    the ±nσ bounds); ``channel`` (an axis such as ``x``) is omitted for a scalar measurement."""
    return join(RESIDUALS, sensor) if channel is None else join(RESIDUALS, sensor, channel)


def sensor_path(sensor: str, channel: str | None = None) -> str:
    """``/sensors/<sensor>[/<channel>]``: raw telemetry of one sensor or one of its channels, as read."""
    return join(SENSORS, sensor) if channel is None else join(SENSORS, sensor, channel)


# ------------------------------------------------------------------------ drop-test path families
def droptest_ranging_sensor_path(channel: str) -> str:
    """``/sensors/ranging/<channel>``: one ranging channel (odometer, radar-gun range or rate), as read."""
    return join(DROPTEST_SENSOR_RANGING, channel)


def droptest_nis_path(sensor: str) -> str:
    """``/plots/nis/<sensor>``: normalised innovation squared of one measurement, per filter step."""
    return join(DROPTEST_PLOT_NIS, sensor)


def droptest_triad_plot_path(triad: str, series: str) -> str:
    """``/plots/triads/<triad>/<series>``: specific force at one accelerometer triad, ``series`` is
    :data:`MEASURED_SERIES` or :data:`PREDICTED_SERIES`."""
    return join(DROPTEST_PLOT_TRIADS, triad, series)


def droptest_sigma_path(group: str, series: str) -> str:
    """``/plots/sigma/<group>/<series>``: 1σ of one state group (position, velocity, ...), ``series``
    :data:`SMOOTHED_SERIES` or :data:`FORWARD_SERIES`."""
    return join(DROPTEST_PLOT_SIGMA, group, series)


# ---------------------------------------------------------------------------- entry path families
def entry_dispersion_plot_path(quantity: str, status: str) -> str:
    """``/plots/dispersion/<quantity>/<status>``: one event quantity of the dispersion members on the
    ``sample`` timeline; ``status`` is :data:`ACCEPTED` or :data:`REJECTED`."""
    return join(ENTRY_PLOT_DISPERSION, quantity, status)


def entry_dispersion_at_pdd_path(status: str) -> str:
    """``/world/dispersion/at_PDD_<status>``: positions of the cloud members at PDD."""
    return join(DISPERSION, f"at_PDD_{status}")


def entry_dispersion_tracks_path(status: str) -> str:
    """``/world/dispersion/tracks_<status>``: thinned trajectories of the cloud members."""
    return join(DISPERSION, f"tracks_{status}")


def entry_residual_path(channel: str, component: str | None = None) -> str:
    """``/residuals/rda/<channel>[/<component>]``: root of one radar residual (children ``value``,
    ``plus_3sigma``, ``minus_3sigma``); ``component`` is an axis (``x``) or a beam (``B0``)."""
    return join(ENTRY_RESIDUALS_RDA, channel) if component is None else join(ENTRY_RESIDUALS_RDA, channel, component)


def entry_radar_plot_path(channel: str, series: str) -> str:
    """``/plots/radar/<channel>_<series>``: a radar channel as measured or as predicted by the smoother
    (``series`` :data:`MEASURED_SERIES` or :data:`PREDICTED_SERIES`)."""
    return join(ENTRY_PLOT_RADAR, f"{channel}_{series}")


def entry_wind_plot_path(component: str) -> str:
    """``/plots/wind/<component>``: root of one wind component (``north``, ``east``) with ±3σ and truth."""
    return join(ENTRY_PLOT_WIND, component)


def entry_wind_profile_path(component: str, series: str | None = None) -> str:
    """``/profiles/wind/<component>[_<series>]``: a wind component against altitude; ``series`` e.g.
    ``plus_1sigma`` (from :func:`bound_names`) or :data:`TRUTH_SERIES`."""
    return join(ENTRY_PROFILE_WIND, component if series is None else f"{component}_{series}")


# ----------------------------------------------------------------------- validation path families
def validation_rms_path(group: str, quantity: str, sigma: bool = False) -> str:
    """``<group>/<quantity>[_sigma]``: RMS error over the runs of one state component under a group root
    (:data:`VALIDATION_RMS_POSITION` ...); ``sigma`` gives the RMS of the reported 1σ instead."""
    if group not in VALIDATION_RMS_GROUPS:
        raise ValueError(f"{group!r} is not a VALIDATION_RMS_* group root")
    return join(group, f"{quantity}_sigma" if sigma else quantity)


# -------------------------------------------------------------------- comparison path families
def compare_run_path(run: str, sub: str) -> str:
    """``/world/run_<run>/<sub>``: the 3D scene of run ``a`` or ``b`` in a comparison recording
    (``track``, ``vehicle`` and the copied vehicle meshes below it)."""
    if run not in COMPARE_RUNS:
        raise ValueError(f"run must be one of {COMPARE_RUNS}, got {run!r}")
    return join(WORLD, f"run_{run}", sub)


def compare_diff_path(quantity: str) -> str:
    """``/compare/diff/<quantity>``: root of the difference A − B of one bounded series (children
    ``value``, ``plus_3sigma``, ``minus_3sigma``: ±3 combined σ around zero); ``quantity`` is the
    series root below ``/plots`` (e.g. ``stroke``, ``position/x``)."""
    return join(COMPARE_DIFF, quantity)


def compare_overlay_path(quantity: str, run: str) -> str:
    """``/compare/overlay/<quantity>/<run>``: the estimate of one bounded series in run ``a`` or ``b``."""
    if run not in COMPARE_RUNS:
        raise ValueError(f"run must be one of {COMPARE_RUNS}, got {run!r}")
    return join(COMPARE_OVERLAY, quantity, run)


def compare_position_path(axis: str) -> str:
    """``/compare/position/<axis>``: difference A − B of the vehicle position along ``x``, ``y``,
    ``z`` (bounded series, ±3 combined σ from the two runs' uncertainty ellipsoids)."""
    return join(COMPARE_POSITION, axis)


_FAMILIES = {
    "radar_beam_path": "/world/vehicle/radar/B<beam>",
    "truth_path": "/world/truth/<sub>",
    "plot_path": "/plots/<quantity>",
    "residual_path": "/residuals/<sensor>[/<channel>]",
    "sensor_path": "/sensors/<sensor>[/<channel>]",
    "droptest_ranging_sensor_path": "/sensors/ranging/<channel>",
    "droptest_nis_path": "/plots/nis/<sensor>",
    "droptest_triad_plot_path": "/plots/triads/<triad>/<series>",
    "droptest_sigma_path": "/plots/sigma/<group>/<series>",
    "entry_dispersion_plot_path": "/plots/dispersion/<quantity>/<status>",
    "entry_dispersion_at_pdd_path": "/world/dispersion/at_PDD_<status>",
    "entry_dispersion_tracks_path": "/world/dispersion/tracks_<status>",
    "entry_residual_path": "/residuals/rda/<channel>[/<component>]",
    "entry_radar_plot_path": "/plots/radar/<channel>_<series>",
    "entry_wind_plot_path": "/plots/wind/<component>",
    "entry_wind_profile_path": "/profiles/wind/<component>[_<series>]",
    "validation_rms_path": "/plots/validation/rms/<group>/<quantity>[_sigma]",
    "compare_run_path": "/world/run_<run>/<sub>",
    "compare_diff_path": "/compare/diff/<quantity>",
    "compare_overlay_path": "/compare/overlay/<quantity>/<run>",
    "compare_position_path": "/compare/position/<axis>",
    "meads_port_plot_path": "/plots/ports/<port>/<series>",
    "meads_trade_path": "/plots/trade_study/<quantity>/<level>",
    "meads_truth_mc_path": "/plots/truth_mc/<quantity>/<series>",
    "post2_truth_mc_path": "/plots/post2_truth_mc/<group>/<series>",
    "meads_ekf_plot_path": "/plots/<quantity>/ekf_pass<pass>",
    "meads_scale_factor_path": "/plots/scale_factors/<series>",
    "meads_ekf_innovation_path": "/residuals/pressure_ekf_pass<pass>/<port>",
}


def meads_port_plot_path(port: str, series: str) -> str:
    """``/plots/ports/<port>/<series>``: one flush port's ``measured`` or ``predicted`` pressure."""
    return join(MEADS_PLOT_PORTS, port, series)


def meads_trade_path(quantity: str, level: str) -> str:
    """``/plots/trade_study/<quantity>/<level>``: trade-study 3σ of ``quantity`` at one error level."""
    return join(MEADS_TRADE_STUDY, quantity, level)


def meads_truth_mc_path(quantity: str, series: str) -> str:
    """``/plots/truth_mc/<quantity>/<series>``: the full-error-model Monte Carlo's 3σ of ``quantity``
    (``<estimator>_mc``, ``<estimator>_reported``) or its ``objective``."""
    return join(MEADS_TRUTH_MC, quantity, series)


def post2_truth_mc_path(group: str, series: str) -> str:
    """``/plots/post2_truth_mc/<group>/<series>``: a series of the post2 Monte Carlo against the truth
    (``grid_nees``, ``running_nees`` or ``z`` group)."""
    return join(POST2_TRUTH_MC, group, series)


def meads_ekf_plot_path(quantity: str, pass_index: int) -> str:
    """``/plots/<quantity>/ekf_pass<pass>``: the MEADS EKF pass's estimate of one plotted quantity."""
    return join(PLOTS, quantity, f"ekf_pass{int(pass_index)}")


def meads_scale_factor_path(series: str) -> str:
    """``/plots/scale_factors/<series>``: transducer scale factors, ``pass<i>`` or ``truth``."""
    return join(MEADS_PLOT_SCALE_FACTORS, series)


def meads_ekf_innovation_path(pass_index: int, port: str) -> str:
    """``/residuals/pressure_ekf_pass<pass>/<port>``: one port's EKF pressure innovation (±3σ)."""
    return join(RESIDUALS, f"pressure_ekf_pass{int(pass_index)}", port)


def path_families() -> dict[str, str]:
    """Template of every path-family function, by function name: ``<x>`` is a caller-given part,
    ``[...]`` an optional one (e.g. ``"residual_path": "/residuals/<sensor>[/<channel>]"``)."""
    return dict(_FAMILIES)


def constant_paths() -> dict[str, str]:
    """Every constant entity path of this module, ``{name: path}`` in definition order."""
    return {k: v for k, v in globals().items() if k.isupper() and isinstance(v, str) and v.startswith("/")}


__all__ = [
    "APPLICATION_ID",
    "TIMELINES",
    "VALIDATION_RMS_GROUPS",
    "COMPARE_RUNS",
    "POST2_ROCKET_PLOTS",
    *[k for k, v in list(globals().items()) if k.isupper() and isinstance(v, str) and k != "APPLICATION_ID"],
    "join",
    "part",
    "subtree",
    "bound_names",
    "path_families",
    "constant_paths",
    *_FAMILIES,
]
