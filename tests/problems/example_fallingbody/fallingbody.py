"""A worked example problem: a body falling through the troposphere, seen by a barometer.

It implements :class:`workbench.problems.base.Problem` with the workbench's building blocks
(telemetry files, the EKF and RTS smoother, the recording writer) and is registered by the tests
only (``registry.register(FallingBodyProblem())``).  State ``x = [h, v, b]``: altitude [m], vertical
velocity [m/s] (up positive) and the barometer bias [Pa].

The settings flow every problem follows: the scenario file is validated against :data:`SCHEMA` once,
by :meth:`FallingBodyProblem.settings`, into the frozen :class:`FallSettings` (one small dataclass per
stage: body, release, barometer, filter, synthetic); every other method receives those settings and
nothing below the problem object sees the scenario.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.estimation.ekf import ErrorStateLayout, ForwardPass, Measurement, run_filter
from workbench.estimation.smoother import rts_smooth
from workbench.io.scenario import RunInfo, Scenario
from workbench.io.schema import REQUIRED, Key, Schema, Table
from workbench.io.telemetry import read_telemetry, write_telemetry
from workbench.problems.base import ExportTable, KeyMoment, McOutcome, RunOptions, Synthesized
from workbench.recording import layout
from workbench.recording.dispatch import StageDispatch
from workbench.recording.moments import log_key_moments
from workbench.recording.writer import open_recording

G = 9.80665  # gravity [m/s^2]
T0, LAPSE, P0, R_AIR = 288.15, 0.0065, 101325.0, 287.053  # ISA troposphere: K, K/m, Pa, J/(kg K)
LAYOUT = ErrorStateLayout(3)  # no quaternion: the error state is the state

#: Every scenario key, once (type, unit, default, meaning); unknown keys are an error.
SCHEMA = Schema(
    "fallingbody",
    "1-D falling body with a barometer (worked example)",
    (
        Table(
            "scenario",
            "what the run is",
            (
                Key("name", "str", REQUIRED, meaning="names the run"),
                Key("kind", "str", REQUIRED, meaning='`"fallingbody"`'),
                Key("description", "str", "", meaning="one line for listings"),
            ),
        ),
        Table(
            "body",
            "the falling body",
            (
                Key("mass_kg", "float", REQUIRED, "kg", "mass"),
                Key("cda_m2", "float", REQUIRED, "m^2", "drag coefficient x reference area"),
            ),
        ),
        Table(
            "release",
            "release state (the filter's prior)",
            (
                Key("altitude_m", "float", REQUIRED, "m", "nominal release altitude"),
                Key("sigma_altitude_m", "float", 20.0, "m", "1-sigma of the release altitude"),
            ),
        ),
        Table(
            "barometer",
            "the sensor",
            (
                Key("rate_hz", "float", 20.0, "Hz", "sample rate"),
                Key("noise_pa", "float", 8.0, "Pa", "white noise, 1-sigma"),
                Key("bias_sigma_pa", "float", 60.0, "Pa", "constant bias, 1-sigma"),
            ),
        ),
        Table(
            "filter",
            "estimator tuning",
            (Key("accel_psd", "float", 0.05, "(m/s^2)^2/Hz", "process noise on the velocity"),),
        ),
        Table(
            "telemetry",
            "user files (ignored by a synthetic scenario)",
            (Key("baro", "str", None, meaning="barometer CSV: `pressure [hPa]`"),),
        ),
        Table(
            "synthetic",
            "simulate instead of reading telemetry",
            (
                Key("seed", "int", 0, meaning="seed of the sensor errors"),
                Key("duration_s", "float", 40.0, "s", "simulated fall duration"),
            ),
        ),
    ),
)


@dataclass(frozen=True)
class Body:
    """The falling body: ``mass_kg`` [kg], ``cda_m2`` drag coefficient × area [m²]."""

    mass_kg: float
    cda_m2: float

    @property
    def k_drag(self) -> float:
        """``CdA / 2m`` [m²/kg]."""
        return 0.5 * self.cda_m2 / self.mass_kg


@dataclass(frozen=True)
class Barometer:
    """``rate_hz`` [Hz], white ``noise_pa`` and constant-bias ``bias_sigma_pa`` 1σ [Pa]."""

    rate_hz: float
    noise_pa: float
    bias_sigma_pa: float


@dataclass(frozen=True)
class FallSettings:
    """The frozen settings of one run (defaults filled from :data:`SCHEMA`): the body, the release
    ``altitude_m`` and its ``sigma_altitude_m`` [m], the barometer, the filter's ``accel_psd``
    [(m/s²)²/Hz], the telemetry file (absolute path or None) and the truth's ``duration_s`` [s]."""

    run: RunInfo
    body: Body
    altitude_m: float
    sigma_altitude_m: float
    barometer: Barometer
    accel_psd: float
    baro_file: Path | None
    duration_s: float

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> FallSettings:
        """Validate ``scenario`` against :data:`SCHEMA` and build the settings."""
        v = SCHEMA.validate(scenario.data, scenario.path)
        run = RunInfo.from_scenario(scenario)
        baro = v["telemetry"]["baro"]
        return cls(
            run=run,
            body=Body(**v["body"]),
            altitude_m=v["release"]["altitude_m"],
            sigma_altitude_m=v["release"]["sigma_altitude_m"],
            barometer=Barometer(**v["barometer"]),
            accel_psd=v["filter"]["accel_psd"],
            baro_file=None if baro is None else run.resolve(baro),
            duration_s=v["synthetic"]["duration_s"],
        )


def pressure(h: np.ndarray) -> np.ndarray:
    """ISA tropospheric static pressure [Pa] at altitude ``h`` [m] (any shape)."""
    return P0 * (1.0 - LAPSE * np.asarray(h) / T0) ** (G / (R_AIR * LAPSE))


def density(h: np.ndarray) -> np.ndarray:
    """ISA tropospheric density [kg/m^3] at altitude ``h`` [m]."""
    return pressure(h) / (R_AIR * (T0 - LAPSE * np.asarray(h)))


def fall_step(x: np.ndarray, dt: float, k_drag: float) -> np.ndarray:
    """One RK4 step of ``h' = v, v' = -g - k rho(h) v |v|`` (``k = CdA / 2m`` [m^2/kg]); x (..., 2+)."""

    def f(y):
        return np.stack([y[..., 1], -G - k_drag * density(y[..., 0]) * y[..., 1] * np.abs(y[..., 1])], -1)

    y = x[..., :2]
    k1 = f(y)
    k2 = f(y + 0.5 * dt * k1)
    k3 = f(y + 0.5 * dt * k2)
    k4 = f(y + dt * k3)
    out = np.array(x, dtype=float)
    out[..., :2] = y + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


@dataclass(frozen=True)
class BaroData:
    """Stage 1: the barometer samples, ``t`` (n,) [s], ``p`` (n,) [Pa]."""

    t: np.ndarray
    p: np.ndarray


@dataclass(frozen=True)
class ForwardStage:
    """Stage 2: the EKF forward pass over the barometer times."""

    forward: ForwardPass


@dataclass(frozen=True)
class FallResult:
    """Final stage: smoothed ``x`` (n, 3) and ``P`` (n, 3, 3) at ``t`` (n,), plus ``summary``."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    forward: ForwardPass
    summary: dict


class _Drawer:
    """Draws the stages as time series (pressure, altitude, residuals) with the writer API; the
    entity paths come from :mod:`workbench.recording.layout`, the stage -> handler map from a
    :class:`~workbench.recording.dispatch.StageDispatch` (an unknown stage is a ``TypeError``)."""

    def __init__(self, rec, truth):
        self.rec, self.truth = rec, truth
        self.handle = StageDispatch({BaroData: self._baro, ForwardStage: self._forward, FallResult: self._result})

    def _baro(self, stage: BaroData) -> None:
        self.rec.scalars(layout.sensor_path("baro", "pressure"), stage.t, stage.p, names="p [Pa]")

    def _forward(self, stage: ForwardStage) -> None:
        fp = stage.forward
        self.rec.scalars(layout.join(layout.plot_path("altitude"), "forward"), fp.t, fp.x_post[:, 0], names="forward")
        baro = fp.innovations["baro"]
        self.rec.scalars(layout.join(layout.residual_path("baro"), "value"), baro.t, baro.y[:, 0])

    def _result(self, stage: FallResult) -> None:
        alt = layout.plot_path("altitude")
        s3 = 3.0 * np.sqrt(stage.P[:, 0, 0])
        self.rec.scalars(layout.join(alt, "smoothed"), stage.t, stage.x[:, 0], names="smoothed")
        self.rec.scalars(layout.join(alt, "plus_3sigma"), stage.t, stage.x[:, 0] + s3)
        self.rec.scalars(layout.join(alt, "minus_3sigma"), stage.t, stage.x[:, 0] - s3)
        if self.truth is not None:
            self.rec.scalars(layout.join(alt, "truth"), self.truth["t"], self.truth["h"], names="truth")

    def finish(self, result: object, summary: dict) -> None:
        self.rec.report(FallingBodyProblem().scorecard(summary))
        log_key_moments(self.rec, summary.get("key_moments", []))


class FallingBodyProblem:
    """1-D fall with drag observed by a barometer (kind ``fallingbody``)."""

    kind = "fallingbody"
    title = "fall"
    schema = SCHEMA

    def settings(self, scenario: Scenario) -> FallSettings:
        """The run's frozen settings (:meth:`FallSettings.from_scenario`)."""
        return FallSettings.from_scenario(scenario)

    def telemetry_files(self, settings: FallSettings, folder: Path | None = None) -> dict[str, Path]:
        """``{"baro": baro.csv}`` from ``[telemetry] baro`` or inside ``folder``."""
        if folder is not None:
            return {"baro": Path(folder) / "baro.csv"}
        if settings.baro_file is None or not settings.baro_file.exists():
            from workbench.io.scenario import ScenarioError

            raise ScenarioError(settings.run.path, "telemetry.baro", f"file not found: {settings.baro_file}")
        return {"baro": settings.baro_file}

    def synthesize(self, settings: FallSettings, out_dir: Path, seed: int) -> Synthesized:
        """Simulate the fall (RK4, 100 Hz) and write ``baro.csv`` (hPa) and ``truth.npz``."""
        rng = np.random.default_rng(seed)
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        k = settings.body.k_drag
        h0 = settings.altitude_m + settings.sigma_altitude_m * rng.standard_normal()
        dt = 0.01
        n = int(round(settings.duration_s / dt))
        x = np.empty((n + 1, 2))
        x[0] = (h0, 0.0)
        for i in range(n):
            x[i + 1] = fall_step(x[i], dt, k)
        t = np.arange(n + 1) * dt
        baro_spec = settings.barometer
        every = int(round(1.0 / (baro_spec.rate_hz * dt)))
        tb, hb = t[::every], x[::every, 0]
        bias = baro_spec.bias_sigma_pa * rng.standard_normal()
        p = pressure(hb) + bias + baro_spec.noise_pa * rng.standard_normal(tb.size)
        baro = write_telemetry(out / "baro.csv", tb, {"pressure": (p, "hPa")}, meta={"source": "synthetic"})
        np.savez(out / "truth.npz", t=t, h=x[:, 0], v=x[:, 1], bias=bias)
        return Synthesized({"baro": baro}, out / "truth.npz")

    def load_truth(self, path: Path) -> dict:
        """The arrays of ``truth.npz``: t, h, v [SI] and the drawn bias [Pa]."""
        with np.load(path) as z:
            return {k: z[k] for k in z.files}

    def reconstruct(self, settings: FallSettings, telemetry, options: RunOptions):
        """Read the barometer, run the EKF forward pass, then the RTS smoother."""
        tel = read_telemetry(telemetry["baro"], required={"pressure": "pressure"})
        t, p = tel.time, tel.channel("pressure")
        yield BaroData(t, p)
        k = settings.body.k_drag
        q = settings.accel_psd
        r = np.array([[settings.barometer.noise_pa**2]])
        x0 = np.array([settings.altitude_m, 0.0, 0.0])
        sigma0 = [settings.sigma_altitude_m, 0.1, settings.barometer.bias_sigma_pa]
        fp = run_filter(
            x0,
            np.diag(np.square(sigma0)),
            t,
            transition=lambda x, t0, t1: (fall_step(x, t1 - t0, k), None),
            process_noise=lambda x, t0, t1: np.diag([0.0, q * (t1 - t0), 0.0]),
            measurements_at=lambda i, ti, xi: [Measurement("baro", p[i : i + 1], r, lambda x: pressure(x[:1]) + x[2])],
            layout=LAYOUT,
        )
        yield ForwardStage(fp)
        sm = rts_smooth(fp, LAYOUT)
        sd = np.sqrt(sm.P[-1].diagonal())
        end = {"t_s": float(t[-1]), "h_m": float(sm.x[-1, 0]), "sigma_h_m": float(sd[0])}
        end |= {"v_mps": float(sm.x[-1, 1]), "sigma_v_mps": float(sd[1])}
        summary = {"scenario": settings.run.name, "kind": self.kind, "samples": int(t.size), "end": end}
        summary["bias_pa"] = {"value": float(sm.x[0, 2]), "sigma": float(np.sqrt(sm.P[0, 2, 2]))}
        yield FallResult(sm.t, sm.x, sm.P, fp, summary)

    def summary(self, result: FallResult) -> dict:
        """A copy of the result's summary."""
        return dict(result.summary)

    def key_moments(self, result: FallResult) -> list[KeyMoment]:
        """The first barometer sample, the fastest descent (smoothed) and the last sample."""
        t, v = result.t, result.x[:, 1]
        k = int(np.argmax(np.abs(v)))
        return [
            KeyMoment("first_sample", float(t[0]), f"first barometer sample, h {result.x[0, 0]:.0f} m"),
            KeyMoment(
                "fastest", float(t[k]), f"fastest descent {abs(v[k]):.1f} m/s", (float(t[k]) - 2.0, float(t[k]) + 2.0)
            ),
            KeyMoment("end", float(t[-1]), f"last sample, h {result.x[-1, 0]:.0f} m"),
        ]

    def score(self, result: FallResult, truth: dict) -> dict:
        """Smoothed altitude errors against the truth (max, RMS, fraction inside 3σ) and the bias error."""
        err = result.x[:, 0] - np.interp(result.t, truth["t"], truth["h"])
        z = np.abs(err) / np.sqrt(result.P[:, 0, 0])
        return {
            "max_abs_h_error_m": float(np.max(np.abs(err))),
            "rms_h_error_m": float(np.sqrt(np.mean(err**2))),
            "max_normalized_h_error": float(np.max(z)),
            "h_inside_3sigma_fraction": float(np.mean(z <= 3.0)),
            "bias_error_pa": float(result.x[0, 2] - truth["bias"]),
        }

    def scorecard(self, summary: dict) -> str:
        """Markdown: end state and, when scored, the altitude errors."""
        e = summary["end"]
        md = f"# {summary['scenario']} scorecard\n\n| quantity | value |\n|---|---|\n"
        md += f"| altitude at {e['t_s']:.1f} s | {e['h_m']:.1f} ± {e['sigma_h_m']:.1f} m |\n"
        if "truth" in summary:
            tr = summary["truth"]
            md += f"| max altitude error | {tr['max_abs_h_error_m']:.2f} m |\n"
            md += f"| inside 3σ | {100 * tr['h_inside_3sigma_fraction']:.1f} % |\n"
        return md

    def headline(self, summary: dict) -> str:
        """End altitude ± 1σ."""
        return f"end altitude {summary['end']['h_m']:.1f} ± {summary['end']['sigma_h_m']:.1f} m (1σ)"

    @contextlib.contextmanager
    def open_recording(self, path: Path, settings: FallSettings, truth, properties: dict):
        """A recording with the writer's defaults (no custom layout)."""
        with open_recording(path, settings.run.name, properties=properties) as rec:
            yield _Drawer(rec, truth)

    def export_columns(self, result: FallResult) -> ExportTable:
        """Smoothed altitude, velocity and their 1σ."""
        sd = np.sqrt(np.einsum("nii->ni", result.P))
        cols = {"h": (result.x[:, 0], "m"), "sigma_h": (sd[:, 0], "m")}
        cols |= {"v": (result.x[:, 1], "m/s"), "sigma_v": (sd[:, 1], "m/s")}
        return ExportTable(result.t, cols, "local vertical, up positive")

    def monte_carlo(self, settings, out_dir, options, progress) -> McOutcome:
        """Not provided by this example."""
        raise NotImplementedError("the fallingbody example has no Monte Carlo analysis")
