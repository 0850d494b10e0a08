"""Aerodynamic database of an entry vehicle: capsule / descent-module tables, parachute, mass properties.

The Schiaparelli AErodynamic DataBase (AEDB) tabulates the axial and normal coefficients of the
descent module and of the parachute against Knudsen number, Mach number and angle of attack
(AMELIA Sect. 9).  This module holds such tables (:class:`AeroTable`, :class:`ParachuteTable`),
the vehicle that carries them (:class:`EntryVehicle`), the schema of the vehicle asset
(:data:`VEHICLE_SCHEMA`) and its loader (:func:`load_vehicle`, e.g. ``assets/vehicles/schiaparelli.toml``).

Conventions (GNC body frame G, origin at the CoG, +Z along the symmetry axis towards the back
shell; during entry the air-relative velocity is along −Z_G):

* Total angle of attack ``α`` [rad] = angle between −Z_G and the air-relative velocity of the
  vehicle ``v_rel_G``: ``cos α = −v_rel_G[2] / |v_rel_G|``.
* Axial force ``F_Z = +CA q S`` along +Z_G (drag of the heat shield gives +Z specific force).
* Normal force ``F_⊥ = −CN q S e_⊥`` with ``e_⊥`` the unit lateral part ``(vx, vy, 0)/|·|`` of
  ``v_rel_G``: CN > 0 pushes against the lateral velocity (standard body-axis convention,
  N along −z_b for α > 0).  A 70° sphere-cone has small positive CN, hence negative lift.
* Pitching moment about the CoG ``M = Cm q S L k̂`` with ``k̂ = unit(v̂_rel × (−Z_G))``, the axis
  about which a positive rotation *increases* α: Cm < 0 is restoring (statically stable).
* Pitch damping ``M_q = Cmq q S L² / (2V) ω_⊥`` with ``ω_⊥ = (ωx, ωy, 0)``; Cmq < 0 damps.
* ``q = ½ ρ V²`` [Pa] with V = |v_rel|, S = ``ref_area`` [m²], L = ``ref_length`` [m].
* Knudsen number ``Kn = λ / L`` on the vehicle diameter (``Atmosphere.knudsen``).

Tables interpolate trilinearly in (Mach, log10 Kn, α) and clamp outside the grid (the end-node
values hold), so the database is always defined.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, load_file

__all__ = ["AeroTable", "ParachuteTable", "EntryVehicle", "VEHICLE_SCHEMA", "load_vehicle", "knudsen_bridge"]


def _locate(grid: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower node index (..,) and clamped weight in [0, 1] of x on a strictly increasing grid (n ≥ 2)."""
    i = np.clip(np.searchsorted(grid, x, side="right") - 1, 0, grid.size - 2)
    w = np.clip((x - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0)
    return i, w


def _locate_scalar(grid: list[float], x: float) -> tuple[int, float]:
    n = len(grid)
    i = min(max(bisect.bisect_right(grid, x) - 1, 0), n - 2)
    g0, g1 = grid[i], grid[i + 1]
    w = (x - g0) / (g1 - g0)
    return i, (0.0 if w < 0.0 else 1.0 if w > 1.0 else w)


def knudsen_bridge(kn: np.ndarray, kn_continuum: float = 1e-3, kn_free_molecular: float = 10.0) -> np.ndarray:
    """Bridging weight in [0, 1] between continuum (0) and free-molecular (1) coefficients.

    ``B = sin²(π/2 · (log10 Kn − log10 Kn_c) / (log10 Kn_fm − log10 Kn_c))`` clamped outside
    ``[Kn_c, Kn_fm]``; with the defaults 1e-3 and 10 it is the classic Mars Pathfinder / Viking
    bridging ``sin²(π/8 (3 + log10 Kn))`` (Wilmoth et al., "Rarefied transitional bridging of
    blunt body aerodynamics", 1998).  ``kn`` any shape [-].
    """
    x = (np.log10(np.asarray(kn, dtype=float)) - math.log10(kn_continuum)) / (
        math.log10(kn_free_molecular) - math.log10(kn_continuum)
    )
    return np.sin(0.5 * np.pi * np.clip(x, 0.0, 1.0)) ** 2


@dataclass(frozen=True, eq=False)
class AeroTable:
    """Coefficients of one aerodynamic configuration vs (Mach, log10 Kn, total AoA).

    Attributes:
        name: configuration name ("capsule", "descent_module").
        mach: Mach nodes (n_mach,), strictly increasing.
        log10_kn: log10 Knudsen nodes (n_kn,), strictly increasing (Kn on ``ref_length``).
        alpha: total angle-of-attack nodes (n_alpha,) [rad], strictly increasing.
        ca, cn, cm: axial, normal and pitching-moment (about the CoG) coefficients, each
            (n_mach, n_kn, n_alpha) [-]; sign conventions in the module docstring.
        cmq: pitch-damping derivative [-] (per ``ω L / (2V)``), < 0 damps.
        ref_area: reference area S [m²]; ref_length: reference length L [m] (diameter).

    Every axis needs ≥ 2 nodes (repeat a value to make a coefficient independent of an axis).
    ``eq=False``: equality is identity (array fields).
    """

    name: str
    mach: np.ndarray
    log10_kn: np.ndarray
    alpha: np.ndarray
    ca: np.ndarray
    cn: np.ndarray
    cm: np.ndarray
    cmq: float
    ref_area: float
    ref_length: float

    def __post_init__(self) -> None:
        axes = {}
        for nm in ("mach", "log10_kn", "alpha"):
            a = np.array(getattr(self, nm), dtype=float)
            if a.ndim != 1 or a.size < 2 or np.any(np.diff(a) <= 0) or not np.all(np.isfinite(a)):
                raise ValueError(f"AeroTable {self.name!r}: {nm} must be 1-D, strictly increasing, >= 2 nodes")
            a.flags.writeable = False
            object.__setattr__(self, nm, a)
            axes[nm] = a.size
        shape = (axes["mach"], axes["log10_kn"], axes["alpha"])
        for nm in ("ca", "cn", "cm"):
            a = np.array(getattr(self, nm), dtype=float)
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise ValueError(f"AeroTable {self.name!r}: {nm} must be finite with shape {shape}, got {a.shape}")
            a.flags.writeable = False
            object.__setattr__(self, nm, a)
        if not (self.ref_area > 0 and self.ref_length > 0):
            raise ValueError(f"AeroTable {self.name!r}: ref_area and ref_length must be > 0")
        object.__setattr__(self, "cmq", float(self.cmq))
        # plain-Python copies for the scalar fast path used inside integrator loops
        object.__setattr__(self, "_grids", (self.mach.tolist(), self.log10_kn.tolist(), self.alpha.tolist()))
        object.__setattr__(self, "_stack", np.stack([self.ca, self.cn, self.cm], axis=-1))
        object.__setattr__(self, "_stack_list", self._stack.tolist())  # nested lists for the scalar path

    def coefficients(self, mach, kn, alpha) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(CA, CN, Cm)`` at Mach ``mach`` [-], Knudsen ``kn`` [-] (not log) and total AoA ``alpha`` [rad].

        Inputs broadcast against each other (any shape); clamped trilinear interpolation in
        (Mach, log10 Kn, α).  Returns three arrays of the broadcast shape.
        """
        m, k, a = np.broadcast_arrays(
            np.asarray(mach, float), np.log10(np.maximum(np.asarray(kn, float), 1e-300)), np.asarray(alpha, float)
        )
        i, wi = _locate(self.mach, m)
        j, wj = _locate(self.log10_kn, k)
        l, wl = _locate(self.alpha, a)
        T = self._stack
        out = 0.0
        for di, fi in ((0, 1.0 - wi), (1, wi)):
            for dj, fj in ((0, 1.0 - wj), (1, wj)):
                for dl, fl in ((0, 1.0 - wl), (1, wl)):
                    out = out + (fi * fj * fl)[..., None] * T[i + di, j + dj, l + dl]
        out = np.asarray(out)
        return out[..., 0], out[..., 1], out[..., 2]

    def coefficients_scalar(self, mach: float, kn: float, alpha: float) -> tuple[float, float, float]:
        """Scalar fast path of :meth:`coefficients` (same interpolation) for integrator loops; floats."""
        gm, gk, ga = self._grids
        i, wi = _locate_scalar(gm, mach)
        j, wj = _locate_scalar(gk, math.log10(kn) if kn > 0.0 else -300.0)
        l, wl = _locate_scalar(ga, alpha)
        # collapse axis by axis (Mach, then Kn, then α) in Python floats: the same IEEE operations in
        # the same order as the (2, 2, 2, 3) numpy slice version, so the same bits, ~5x faster (the
        # entry truth calls this ~270 000 times a run)
        s0, s1 = self._stack_list[i], self._stack_list[i + 1]
        out = []
        for k in range(3):
            u = []
            for dl in (0, 1):
                a0 = s0[j][l + dl][k]
                b0 = s1[j][l + dl][k]
                a1 = s0[j + 1][l + dl][k]
                b1 = s1[j + 1][l + dl][k]
                v0 = a0 + wi * (b0 - a0)
                v1 = a1 + wi * (b1 - a1)
                u.append(v0 + wj * (v1 - v0))
            out.append(u[0] + wl * (u[1] - u[0]))
        return out[0], out[1], out[2]


@dataclass(frozen=True, eq=False)
class ParachuteTable:
    """Parachute drag coefficient vs Mach (referred to ``ref_area``, the nominal canopy area).

    Attributes: ``name``; ``mach`` (n,) strictly increasing; ``cd`` (n,) [-]; ``ref_area`` [m²]
    (π D0²/4 of the nominal diameter D0); ``mass`` [kg] (canopy + lines + riser).
    """

    name: str
    mach: np.ndarray
    cd: np.ndarray
    ref_area: float
    mass: float

    def __post_init__(self) -> None:
        m = np.array(self.mach, dtype=float)
        c = np.array(self.cd, dtype=float)
        if m.ndim != 1 or m.size < 2 or np.any(np.diff(m) <= 0) or c.shape != m.shape or np.any(c <= 0):
            raise ValueError(f"ParachuteTable {self.name!r}: mach strictly increasing (>= 2), cd positive, same size")
        if not (self.ref_area > 0 and self.mass > 0):
            raise ValueError(f"ParachuteTable {self.name!r}: ref_area and mass must be > 0")
        m.flags.writeable = False
        c.flags.writeable = False
        object.__setattr__(self, "mach", m)
        object.__setattr__(self, "cd", c)
        object.__setattr__(self, "_lists", (m.tolist(), c.tolist()))

    def cd_at(self, mach) -> np.ndarray:
        """Drag coefficient [-] at Mach ``mach`` (any shape), linear interpolation, clamped at the ends."""
        return np.interp(np.asarray(mach, dtype=float), self.mach, self.cd)

    def cd_scalar(self, mach: float) -> float:
        """Scalar fast path of :meth:`cd_at` (float in, float out)."""
        gm, gc = self._lists
        i, w = _locate_scalar(gm, mach)
        return gc[i] + w * (gc[i + 1] - gc[i])


@dataclass(frozen=True, eq=False)
class EntryVehicle:
    """An entry capsule with its parachute, loaded from a TOML asset by :func:`load_vehicle`.

    Attributes (SI, GNC body frame G, origin at the CoG):
        name: display name.
        mass_entry: total mass at entry incl. parachute [kg].
        mass_front_shield: front shield mass released at FSR [kg].
        mass_back_shell: back shell mass released at BSR (end of data) [kg].
        inertia_G: inertia tensor about the CoG at entry (3, 3) [kg m²].
        diameter: maximum diameter [m] (Knudsen reference length); nose_radius [m].
        capsule: :class:`AeroTable` of the entry configuration (front shield + back shell + DM).
        descent_module: :class:`AeroTable` after FSR (back shell + DM under the parachute).
        parachute: :class:`ParachuteTable`.
        attach_point_G: riser attachment on the back shell apex (3,) [m].
        riser_length: unstretched riser + suspension-line length [m] (attach point to canopy);
        riser_stiffness [N/m]; riser_damping [N s/m] (spring-damper, slack when shorter).
    """

    name: str
    mass_entry: float
    mass_front_shield: float
    mass_back_shell: float
    inertia_G: np.ndarray
    diameter: float
    nose_radius: float
    capsule: AeroTable
    descent_module: AeroTable
    parachute: ParachuteTable
    attach_point_G: np.ndarray
    riser_length: float
    riser_stiffness: float
    riser_damping: float

    def mass_at(self, phase) -> np.ndarray:
        """Mass [kg] of the module body (the part the IMU rides on) per phase, any shape.

        phase 0 (entry): ``mass_entry`` (parachute packed inside); phase 1 (PDD..FSR):
        ``mass_entry − parachute.mass`` (the canopy is a separate body: add ``parachute.mass``
        for the joint drag equation, AMELIA Eq. 5); phase 2 (FSR..BSR): also minus
        ``mass_front_shield``.  Ablation mass loss is neglected.
        """
        ph = np.asarray(phase)
        m1 = self.mass_entry - self.parachute.mass
        return np.where(ph <= 0, self.mass_entry, np.where(ph == 1, m1, m1 - self.mass_front_shield)).astype(float)

    def aero_at(self, phase: int) -> AeroTable:
        """The :class:`AeroTable` of a phase: ``capsule`` for 0 and 1, ``descent_module`` for 2."""
        return self.descent_module if int(phase) >= 2 else self.capsule


# ------------------------------------------------------------------------------------- loading


_F, _S, _L, _V = "float", "str", "list", "vec3"


def _aero_keys(kind: str) -> tuple[Key, ...]:
    """The keys of an ``[aero.capsule]`` / ``[aero.descent_module]`` table (compact AEDB form)."""
    return (
        Key("name", _S, None, meaning=f"display name; absent: `{kind}`"),
        Key("mach", _L, REQUIRED, "1", "Mach nodes (n_mach), increasing", ge=0.0),
        Key("alpha_deg", _L, REQUIRED, "deg", "total angle-of-attack nodes (n_alpha), increasing", ge=0.0, le=180.0),
        Key("ca", _L, REQUIRED, "1", "continuum axial coefficient, n_mach rows of n_alpha"),
        Key("cn", _L, REQUIRED, "1", "continuum normal coefficient, n_mach × n_alpha"),
        Key("cm", _L, REQUIRED, "1", "continuum pitching-moment coefficient about the CoG, n_mach × n_alpha"),
        Key("cmq", _F, REQUIRED, "1", "pitch-damping coefficient (< 0 damps)"),
        Key("ref_area_m2", _F, None, "m²", "reference area; absent: π d²/4 with d = `vehicle.diameter_m`", gt=0.0),
        Key("ref_length_m", _F, None, "m", "reference length; absent: `vehicle.diameter_m`", gt=0.0),
        Key("ca_fm", _L, None, "1", "free-molecular CA (n_alpha); present: the table is bridged in Kn"),
        Key("cn_fm", _L, None, "1", "free-molecular CN (n_alpha); needed with `ca_fm`"),
        Key("cm_fm", _L, None, "1", "free-molecular Cm (n_alpha); needed with `ca_fm`"),
        Key("kn_continuum", _F, None, "1", "Knudsen number below which the flow is continuum; with `ca_fm`", gt=0.0),
        Key(
            "kn_free_molecular",
            _F,
            None,
            "1",
            "Knudsen number above which it is free-molecular (> `kn_continuum`); with `ca_fm`",
            gt=0.0,
        ),
        Key("log10_kn", _L, None, "1", "log10 Kn nodes of the bridged table; with `ca_fm`"),
    )


#: The schema of an entry-vehicle asset (``assets/vehicles/*.toml``), read by :func:`load_vehicle`.
VEHICLE_SCHEMA = Schema(
    "vehicle",
    "entry vehicle asset",
    (
        Table(
            "vehicle",
            "mass properties, geometry and parachute riser (GNC body frame G, origin at the CoG)",
            (
                Key("name", _S, REQUIRED, meaning="display name"),
                Key("half_angle_deg", _F, None, "deg", "sphere-cone half-angle (documentation only)", gt=0.0, lt=90.0),
                Key("diameter_m", _F, REQUIRED, "m", "maximum diameter (Knudsen reference length)", gt=0.0),
                Key("nose_radius_m", _F, REQUIRED, "m", "nose radius", gt=0.0),
                Key("mass_entry_kg", _F, REQUIRED, "kg", "total mass at entry incl. the parachute", gt=0.0),
                Key("mass_front_shield_kg", _F, REQUIRED, "kg", "front shield released at FSR", gt=0.0),
                Key("mass_back_shell_kg", _F, REQUIRED, "kg", "back shell released at BSR", gt=0.0),
                Key("inertia_kgm2", _L, REQUIRED, "kg m²", "inertia tensor about the CoG at entry, 3×3 symmetric PD"),
                Key("attach_point_m", _V, REQUIRED, "m", "riser attachment on the back shell apex [x, y, z]"),
                Key("riser_length_m", _F, REQUIRED, "m", "unstretched riser + suspension-line length", gt=0.0),
                Key("riser_stiffness_n_per_m", _F, REQUIRED, "N/m", "riser spring stiffness", gt=0.0),
                Key("riser_damping_n_s_per_m", _F, REQUIRED, "N s/m", "riser damping"),
            ),
        ),
        Table("aero.capsule", "entry configuration (front shield + back shell + module)", _aero_keys("capsule")),
        Table(
            "aero.descent_module",
            "after FSR (back shell + module under the parachute)",
            _aero_keys("descent_module"),
        ),
        Table(
            "aero.parachute",
            "the parachute",
            (
                Key("name", _S, REQUIRED, meaning="display name"),
                Key("nominal_diameter_m", _F, REQUIRED, "m", "nominal diameter (reference area π D²/4)", gt=0.0),
                Key("mass_kg", _F, REQUIRED, "kg", "canopy mass", gt=0.0),
                Key("mach", _L, REQUIRED, "1", "Mach nodes, increasing", ge=0.0),
                Key("cd", _L, REQUIRED, "1", "drag coefficient at those nodes", gt=0.0),
            ),
        ),
    ),
    noun="vehicle asset",
    intro="Keys of an entry-vehicle asset (`assets/vehicles/*.toml`, read by `models.aerodynamics.load_vehicle`)",
)


def _shaped(path: Path, dotted: str, value, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (cross-field shape check after validation);
    :class:`ScenarioError` naming the file and ``dotted`` otherwise."""
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ScenarioError(path, dotted, "must be a (nested) array of numbers") from None
    if shape is not None and a.shape != shape:
        raise ScenarioError(path, dotted, f"must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ScenarioError(path, dotted, "must be finite")
    return a


def _aero_table(tab: dict, key: str, path: Path, diameter: float) -> AeroTable:
    """Build a 3-D AeroTable from the validated compact AEDB form of ``[aero.<key>]``."""
    pre = f"aero.{key}"
    mach = _shaped(path, f"{pre}.mach", tab["mach"])
    alpha_deg = _shaped(path, f"{pre}.alpha_deg", tab["alpha_deg"])
    nm, na = mach.size, alpha_deg.size
    cont = {c: _shaped(path, f"{pre}.{c}", tab[c], (nm, na)) for c in ("ca", "cn", "cm")}
    if tab["ca_fm"] is not None:  # free-molecular limit + bridging in log Kn
        for k in ("cn_fm", "cm_fm", "kn_continuum", "kn_free_molecular", "log10_kn"):
            if tab[k] is None:
                raise ScenarioError(path, f"{pre}.{k}", "missing (needed with ca_fm: a Kn-bridged table)")
        fm = {c: _shaped(path, f"{pre}.{c}_fm", tab[f"{c}_fm"], (na,)) for c in ("ca", "cn", "cm")}
        kn_c, kn_fm = tab["kn_continuum"], tab["kn_free_molecular"]
        if not kn_fm > kn_c:
            raise ScenarioError(path, f"{pre}.kn_free_molecular", "must exceed kn_continuum")
        log_kn = _shaped(path, f"{pre}.log10_kn", tab["log10_kn"])
        B = knudsen_bridge(10.0**log_kn, kn_c, kn_fm)[None, :, None]
        coef = {c: cont[c][:, None, :] + (fm[c][None, None, :] - cont[c][:, None, :]) * B for c in cont}
    else:  # continuum only: independent of Kn
        log_kn = np.array([-8.0, 4.0])
        coef = {c: np.repeat(cont[c][:, None, :], 2, axis=1) for c in cont}
    try:
        return AeroTable(
            name=key if tab["name"] is None else tab["name"],
            mach=mach,
            log10_kn=log_kn,
            alpha=np.deg2rad(alpha_deg),
            ca=coef["ca"],
            cn=coef["cn"],
            cm=coef["cm"],
            cmq=tab["cmq"],
            ref_area=0.25 * math.pi * diameter**2 if tab["ref_area_m2"] is None else tab["ref_area_m2"],
            ref_length=diameter if tab["ref_length_m"] is None else tab["ref_length_m"],
        )
    except ValueError as exc:
        raise ScenarioError(path, pre, str(exc)) from None


def load_vehicle(path: str | Path) -> EntryVehicle:
    """Read an entry-vehicle asset (TOML, SI; :data:`VEHICLE_SCHEMA`) into an :class:`EntryVehicle`.

    ``[vehicle]`` mass properties (inertia 3×3 symmetric PD), geometry and riser;
    ``[aero.capsule]`` and ``[aero.descent_module]`` the compact AEDB tables (continuum
    n_mach × n_alpha, optionally bridged to the free-molecular limit); ``[aero.parachute]``.
    The 3-D capsule table is ``C(M, Kn, α) = C_cont(M, α) + (C_fm(α) − C_cont(M, α)) B(Kn)`` with
    :func:`knudsen_bridge` ``B``, sampled at the ``log10_kn`` nodes.

    Raises ``FileNotFoundError`` if the file is missing and
    :class:`~workbench.io.scenario.ScenarioError` (a ``ValueError``) naming the file and dotted key
    for malformed TOML, unknown keys (with the nearest valid one), missing keys or bad values.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"vehicle asset not found: {path}")
    data = load_file(path, VEHICLE_SCHEMA)
    v, aero = data["vehicle"], data["aero"]
    d = v["diameter_m"]
    inertia = _shaped(path, "vehicle.inertia_kgm2", v["inertia_kgm2"], (3, 3))
    if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0.0):
        raise ScenarioError(path, "vehicle.inertia_kgm2", "must be symmetric positive definite")
    attach = _shaped(path, "vehicle.attach_point_m", v["attach_point_m"], (3,))
    pc = aero["parachute"]
    pm = _shaped(path, "aero.parachute.mach", pc["mach"])
    pcd = _shaped(path, "aero.parachute.cd", pc["cd"], pm.shape)
    try:
        chute = ParachuteTable(
            name=pc["name"],
            mach=pm,
            cd=pcd,
            ref_area=0.25 * math.pi * pc["nominal_diameter_m"] ** 2,
            mass=pc["mass_kg"],
        )
    except ValueError as exc:
        raise ScenarioError(path, "aero.parachute", str(exc)) from None
    m_entry, m_fs, m_bs = v["mass_entry_kg"], v["mass_front_shield_kg"], v["mass_back_shell_kg"]
    if not m_entry > chute.mass + m_fs + m_bs:
        raise ScenarioError(path, "vehicle.mass_entry_kg", "must exceed parachute + front shield + back shell")
    for a in (inertia, attach):
        a.flags.writeable = False
    return EntryVehicle(
        name=v["name"],
        mass_entry=m_entry,
        mass_front_shield=m_fs,
        mass_back_shell=m_bs,
        inertia_G=inertia,
        diameter=d,
        nose_radius=v["nose_radius_m"],
        capsule=_aero_table(aero["capsule"], "capsule", path, d),
        descent_module=_aero_table(aero["descent_module"], "descent_module", path, d),
        parachute=chute,
        attach_point_G=attach,
        riser_length=v["riser_length_m"],
        riser_stiffness=v["riser_stiffness_n_per_m"],
        riser_damping=v["riser_damping_n_s_per_m"],
    )
