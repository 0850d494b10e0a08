"""Planetary constants: gravity, size, oblateness and the IAU rotation elements of Mars, Titan, Earth.

A :class:`Body` is a small frozen record; the rotation model that uses its IAU elements lives in
:mod:`workbench.core.frames`, the gravity models in :mod:`workbench.core.gravity`.  Everything is
SI (m, s, m³/s²) except the IAU elements, which keep the units of the IAU report (degrees, Julian
centuries and days from J2000 TDB) and say so in their names.

Also the standard gravity :data:`G0` used for lab frames and g-unit conversion.

Sources:

[1] Archinal et al., "Report of the IAU Working Group on Cartographic Coordinates and Rotational
    Elements: 2015", Celest. Mech. Dyn. Astron. 130:22, 2018, as distributed in NAIF
    ``pck00011.tpc`` (pole, prime meridian, radii).
[2] NAIF ``gm_de440.tpc`` (GM).
[3] NSSDC Mars fact sheet (J2); JPL Horizons Mars physical data (rotation rate).
[4] AMELIA Schiaparelli reconstruction (Aboudan et al. 2018), Sect. 7 and Eq. (B.1): MOLA
    reference radius 3396 km.
[5] NIMA TR8350.2, *WGS 84*, 3rd ed. (Earth GM, radii, rotation rate, J2 from C̄20).
[6] IAU WGCCRE 2015 report [1], Table 1 (Earth pole and prime meridian, the simple IAU model;
    not a substitute for IERS precession-nutation).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "G0",
    "PERIODIC_KINDS",
    "Body",
    "MARS",
    "TITAN",
    "EARTH",
    "KNOWN_BODIES",
    "get_body",
]

G0 = 9.80665
"""Standard gravity [m/s²], exact by definition (CGPM 1901): the g unit and lab-frame gravity."""

#: Kinds of IAU periodic terms: ``"alpha0"`` adds ``A sin(φ0 + ν T)`` to the pole right ascension,
#: ``"delta0"`` adds ``A cos(φ0 + ν T)`` to the pole declination, ``"W"`` adds ``A sin(φ0 + ν T)``
#: to the prime meridian (IAU report convention; A, φ0 in degrees, ν in deg/century).
PERIODIC_KINDS = ("alpha0", "delta0", "W")


@dataclass(frozen=True)
class Body:
    """Constants of a planet or moon (SI; IAU rotation elements in degrees as published).

    Attributes:
        name: display name ("Mars").
        gm: gravitational parameter GM [m³/s²].
        equatorial_radius: equatorial radius [m]; also the normalising radius of ``j2``.
        polar_radius: polar radius [m].
        reference_radius: radius of the reference sphere that altitudes are measured from [m]
            (for Mars the MOLA radius 3396.0 km used by AMELIA).
        j2: second zonal harmonic (unnormalised, positive for an oblate body), referred to
            ``equatorial_radius``.
        rotation_rate: sidereal rotation rate [rad/s] (published value; the frames module uses
            the time derivative of the IAU prime meridian instead, which agrees to ~1e-9).
        alpha0_deg, alpha0_rate_deg_per_century: pole right ascension α0 = a + ȧ T (ICRF/J2000).
        delta0_deg, delta0_rate_deg_per_century: pole declination δ0 = d + ḋ T.
        w0_deg, w_rate_deg_per_day: prime meridian W = W0 + Ẇ d.
        periodic_terms: tuple of ``(kind, amplitude_deg, phase0_deg, rate_deg_per_century)`` with
            ``kind`` in :data:`PERIODIC_KINDS`.

    T is Julian centuries and d days since J2000.0 TDB (JD 2451545.0).
    """

    name: str
    gm: float
    equatorial_radius: float
    polar_radius: float
    reference_radius: float
    j2: float
    rotation_rate: float
    alpha0_deg: float
    alpha0_rate_deg_per_century: float
    delta0_deg: float
    delta0_rate_deg_per_century: float
    w0_deg: float
    w_rate_deg_per_day: float
    periodic_terms: tuple[tuple[str, float, float, float], ...] = field(default=())

    def __post_init__(self) -> None:
        for kind, *_ in self.periodic_terms:
            if kind not in PERIODIC_KINDS:
                raise ValueError(f"{self.name}: unknown periodic-term kind {kind!r}; use one of {PERIODIC_KINDS}")
        if self.gm <= 0 or self.equatorial_radius <= 0 or self.polar_radius <= 0 or self.reference_radius <= 0:
            raise ValueError(f"{self.name}: GM and radii must be positive")

    @property
    def surface_gravity(self) -> float:
        """Point-mass gravity GM / R_ref² [m/s²] on the reference sphere (no J2, no rotation)."""
        return self.gm / self.reference_radius**2

    @property
    def flattening(self) -> float:
        """Geometric flattening (a − c) / a [-] from the equatorial and polar radii."""
        return (self.equatorial_radius - self.polar_radius) / self.equatorial_radius


MARS = Body(
    name="Mars",
    gm=42828.37362069909e9,  # gm_de440.tpc [2]
    equatorial_radius=3396.19e3,  # pck00011 [1]
    polar_radius=3376.20e3,  # pck00011 [1]
    reference_radius=3396.0e3,  # MOLA reference radius, AMELIA Eq. (B.1) [4]
    j2=1960.45e-6,  # NSSDC fact sheet [3]
    rotation_rate=7.08822e-5,  # JPL Horizons [3]
    # IAU 2015 (pck00011) [1]
    alpha0_deg=317.269202,
    alpha0_rate_deg_per_century=-0.10927547,
    delta0_deg=54.432516,
    delta0_rate_deg_per_century=-0.05827105,
    w0_deg=176.049863,
    w_rate_deg_per_day=350.891982443297,
    # Largest periodic terms only; pck00011 lists further terms, each far smaller.
    periodic_terms=(
        ("alpha0", 0.419057, 79.398797, 0.5042615),
        ("delta0", 1.591274, 166.325722, 0.5042615),
        ("W", 0.584542, 95.391654, 0.5042615),
    ),
)
"""Mars: IAU 2015 rotation with its three largest periodic terms (pck00011 [1]), GM from
gm_de440 [2], J2 from NSSDC and rotation rate from Horizons [3], MOLA reference radius 3396.0 km
as in AMELIA [4]."""

TITAN = Body(
    name="Titan",
    gm=8978.137095521046e9,  # gm_de440.tpc [2]
    equatorial_radius=2575.15e3,  # pck00011 longest axis [1]
    polar_radius=2574.47e3,  # pck00011 [1]
    # [derived] volumetric mean radius (a b c)^(1/3) of the pck00011 triaxial radii
    reference_radius=float(np.cbrt(2575.15e3 * 2574.78e3 * 2574.47e3)),
    # Engineering value: Iess et al., Science 327:1367 (2010), J2 = 31.808e-6.
    j2=31.808e-6,
    # [derived] from the IAU prime-meridian rate 22.5769768 deg/day
    rotation_rate=float(np.deg2rad(22.5769768) / 86400.0),
    alpha0_deg=39.4827,
    alpha0_rate_deg_per_century=0.0,
    delta0_deg=83.4279,
    delta0_rate_deg_per_century=0.0,
    w0_deg=186.5855,
    w_rate_deg_per_day=22.5769768,
)
"""Titan: pck00011 pole 39.4827°/83.4279° (no secular rates given), W = 186.5855 + 22.5769768 d,
radii 2575.15/2574.78/2574.47 km [1]; GM from gm_de440 [2].  Reference radius is the
[derived] volumetric mean 2574.80 km; J2 = 31.808e-6 is an engineering value from Iess et al.
(2010)."""

EARTH = Body(
    name="Earth",
    gm=3.986004418e14,  # WGS 84 [5]
    equatorial_radius=6378137.0,  # WGS 84 semi-major axis [5]
    polar_radius=6356752.3142,  # WGS 84 semi-minor axis [5]
    reference_radius=6371008.8,  # IUGG mean radius R1 = (2a + b) / 3 of WGS 84
    j2=1.08262998905e-3,  # WGS 84: J2 = -sqrt(5) * C̄20, C̄20 = -0.484166774985e-3 [5]
    rotation_rate=7.292115e-5,  # WGS 84 [5]
    # IAU WGCCRE simple Earth model [6]
    alpha0_deg=0.0,
    alpha0_rate_deg_per_century=-0.641,
    delta0_deg=90.0,
    delta0_rate_deg_per_century=-0.557,
    w0_deg=190.147,
    w_rate_deg_per_day=360.9856235,
)
"""Earth: WGS 84 GM, radii, J2 and rotation rate [5]; IAU WGCCRE pole/prime meridian [6]
(α0 = −0.641 T, δ0 = 90 − 0.557 T, W = 190.147 + 360.9856235 d), good to ~0.1° — enough for a
test-range frame, not for precise Earth orientation.  Mean radius is the IUGG R1."""

KNOWN_BODIES: dict[str, Body] = {b.name.lower(): b for b in (MARS, TITAN, EARTH)}


def get_body(name: str) -> Body:
    """Look up a :class:`Body` by name, case-insensitively ("mars", "TITAN", "Earth").

    Raises:
        KeyError: the name is unknown; the message lists the known bodies.
    """
    key = str(name).strip().lower()
    try:
        return KNOWN_BODIES[key]
    except KeyError:
        known = ", ".join(b.name for b in KNOWN_BODIES.values())
        raise KeyError(f"unknown body {name!r}; known bodies: {known}") from None
