"""The rigid lander body and its airbag lobes: a tetrahedron with a "billiard rack" on each face.

Provides :class:`LanderModel` (mass properties, body mesh, airbag lobes, instrument lever arms),
:func:`load_lander` (reads the TOML asset, e.g. ``assets/landers/mer_drop_lander.toml``),
:func:`tetrahedron_body`, :func:`airbag_lobes`, :func:`airbag_mesh` and :func:`lobe_meshes`.

Geometry follows the REDLand paper [1], "Test article and equipment": the closed MER drop-test
lander is 1.2 m tall with 1.6 m base sides (so it is *not* a regular tetrahedron); each face
carries one airbag of six 2 m lobes in a "billiard rack" (rows of 3, 2, 1).

Body frame B: origin at the centre of mass (CM), +Z from the base petal toward the apex, the
base petal an equilateral triangle in the plane ``z = -cm_height`` whose +Y edge (the one
carrying the PYBP accelerometer triad, REDLand Fig. 4-5) has its midpoint on the +Y axis.

Face / bag order (index into ``body.faces`` and ``LanderModel.lobe_bag``): see :data:`FACE_NAMES`.
Each face is stored ``[a, b, c]`` with outward (counter-clockwise seen from outside) winding, and
``c`` is the face's "opposite" vertex: the apex for side faces, the -Y base vertex for the base.

[1] JPL, REDLand (Reconstruction of Entry, Descent and Landing) paper on the MER airbag drop
    tests at the SPF, 2001 test series, section "Test article and equipment".
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

__all__ = [
    "FACE_NAMES",
    "LanderModel",
    "load_lander",
    "tetrahedron_body",
    "airbag_lobes",
    "airbag_mesh",
    "lobe_meshes",
]

#: Names of the four faces (= airbags) in the order of ``tetrahedron_body(...).faces``.
FACE_NAMES: tuple[str, ...] = ("base", "side_PY", "side_PX", "side_MX")


@dataclass(frozen=True, eq=False)
class LanderModel:
    """Rigid lander with its airbags (SI units, body frame B with origin at the CM).

    ``eq=False``: equality is identity (fields hold numpy arrays and a mesh).

    Attributes:
        name: human-readable name.
        mass: total mass [kg].
        inertia_B: inertia tensor about the CM in B (3, 3) [kg m²].
        body: rigid body mesh in B [m] (watertight, outward normals).
        lobe_centers_B: airbag lobe centres in B (n_lobes, 3) [m].
        lobe_radius: lobe sphere radius [m].
        lobe_bag: bag (= face) index of each lobe (n_lobes,) int, see :data:`FACE_NAMES`.
        pressure_pa: initial absolute bag inflation pressure [Pa].
        gas_volume_m3: shared gas volume of the vented bags [m³].
        gamma: ratio of specific heats of the inflation gas [-].
        damping: fabric/venting damping, pressure-equivalent per m/s of penetration rate [Pa s/m].
        friction: Coulomb friction coefficient airbag/surface [-].
        standoff: gap between a lobe's inner surface and its lander face [m]; negative when the
            lobes wrap the lander (centre closer than one radius to the face), > -lobe_radius.
        ambient_pressure_pa: chamber (or atmosphere) pressure [Pa].
        instruments: lever arms of the sensors from the CM in B, name -> (3,) [m].
    """

    name: str
    mass: float
    inertia_B: np.ndarray
    body: trimesh.Trimesh
    lobe_centers_B: np.ndarray
    lobe_radius: float
    lobe_bag: np.ndarray
    pressure_pa: float
    gas_volume_m3: float
    gamma: float
    damping: float
    friction: float
    standoff: float
    ambient_pressure_pa: float
    instruments: dict[str, np.ndarray] = field(default_factory=dict)


def tetrahedron_body(height: float, base_side: float, cm_height: float) -> trimesh.Trimesh:
    """Tetrahedral lander body in the body frame B (origin at the CM), lengths in m.

    The base is an equilateral triangle of side ``base_side`` in the plane ``z = -cm_height``,
    centred on the Z axis, with the midpoint of one edge (the PYBP edge) on +Y; the apex is at
    ``(0, 0, height - cm_height)``.  Vertices: 0 = -Y base vertex ``(0, -s/√3, z_b)``,
    1 = ``(+s/2, s/(2√3), z_b)``, 2 = ``(-s/2, s/(2√3), z_b)``, 3 = apex.  Faces in the order of
    :data:`FACE_NAMES`, outward winding, last vertex of each face = the vertex opposite the
    "rack base" edge (apex for side faces, vertex 0 for the base).

    Returns a watertight ``trimesh.Trimesh`` (4 vertices, 4 faces, positive volume).
    Raises ``ValueError`` unless ``height > 0``, ``base_side > 0`` and ``0 < cm_height < height``.
    """
    height, base_side, cm_height = float(height), float(base_side), float(cm_height)
    if not (height > 0.0 and base_side > 0.0 and 0.0 < cm_height < height):
        raise ValueError(
            f"tetrahedron_body: need height > 0, base_side > 0, 0 < cm_height < height; "
            f"got height={height}, base_side={base_side}, cm_height={cm_height}"
        )
    s = base_side
    z_b = -cm_height
    r_circ = s / np.sqrt(3.0)  # base centroid to a vertex
    r_in = s / (2.0 * np.sqrt(3.0))  # base centroid to an edge midpoint
    vertices = np.array(
        [
            [0.0, -r_circ, z_b],
            [0.5 * s, r_in, z_b],
            [-0.5 * s, r_in, z_b],
            [0.0, 0.0, height - cm_height],
        ]
    )
    faces = np.array([[2, 1, 0], [1, 2, 3], [0, 1, 3], [2, 0, 3]])
    # enforce outward winding (the CM/origin is strictly inside): flip the first two vertices
    tri = vertices[faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", nrm, tri.mean(axis=1)) < 0.0
    faces[flip] = faces[flip][:, [1, 0, 2]]
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


def _rack_offsets(spacing: float) -> np.ndarray:
    """2-D lobe centres (6, 2) of a 3-2-1 rack with centre spacing ``spacing``, centroid at 0.

    x runs along the row of three, y from that row toward the single lobe.
    """
    a = float(spacing)
    h = a * np.sqrt(3.0) / 2.0
    pts = np.array([[-a, 0.0], [0.0, 0.0], [a, 0.0], [-a / 2, h], [a / 2, h], [0.0, 2.0 * h]])
    return pts - pts.mean(axis=0)


def airbag_lobes(
    body: trimesh.Trimesh,
    lobe_radius: float,
    lobe_spacing: float,
    standoff: float,
    lobes_per_bag: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the airbag lobes, one "billiard rack" per face of a tetrahedral body.

    For face ``[a, b, c]`` (outward winding) the rack is an equilateral arrangement of 6 lobes in
    rows of 3-2-1 with centre-to-centre spacing ``lobe_spacing`` [m]: the row of three is parallel
    to edge a-b, the single lobe points toward vertex c (so the rack is "oriented like the face"),
    and the centroid of the 6 centres lies on the face centroid pushed outward along the unit
    face normal by ``lobe_radius + standoff`` [m] -- every lobe sphere then clears its face plane
    by ``standoff`` (a negative standoff means the spheres cut the face plane: lobes wrapping the
    lander).  Frame: whatever frame ``body`` is in (B for the lander).

    Returns ``(centers (n_faces*6, 3) [m], bag_index (n_faces*6,) int)``, lobes grouped by face
    in face order.  Only ``lobes_per_bag == 6`` (the MER rack) is supported.
    """
    if int(lobes_per_bag) != 6:
        raise ValueError(f"airbag_lobes: only the 3-2-1 rack (6 lobes per bag) is supported, got {lobes_per_bag}")
    V = np.asarray(body.vertices, dtype=float)
    F = np.asarray(body.faces, dtype=int)
    offsets = _rack_offsets(lobe_spacing)
    centers = []
    bag = []
    for k, (ia, ib, ic) in enumerate(F):
        a, b, c = V[ia], V[ib], V[ic]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        ex = (b - a) / np.linalg.norm(b - a)
        ey = np.cross(n, ex)  # in-plane, perpendicular to a-b
        if np.dot(ey, c - a) < 0.0:
            ey = -ey
        origin = (a + b + c) / 3.0 + (float(lobe_radius) + float(standoff)) * n
        centers.append(origin + offsets[:, :1] * ex + offsets[:, 1:] * ey)
        bag.append(np.full(6, k, dtype=int))
    return np.concatenate(centers, axis=0), np.concatenate(bag)


def lobe_meshes(model: LanderModel, subdivisions: int = 2) -> list[trimesh.Trimesh]:
    """One mesh per bag (list indexed like :data:`FACE_NAMES`): its lobes as icospheres in B [m]."""
    out = []
    for k in range(int(model.lobe_bag.max()) + 1):
        spheres = []
        for c in model.lobe_centers_B[model.lobe_bag == k]:
            s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=model.lobe_radius)
            s.apply_translation(c)
            spheres.append(s)
        out.append(trimesh.util.concatenate(spheres))
    return out


def airbag_mesh(model: LanderModel, subdivisions: int = 2) -> trimesh.Trimesh:
    """All airbag lobes as one mesh of (overlapping, not unioned) icospheres in B [m], for display."""
    return trimesh.util.concatenate(lobe_meshes(model, subdivisions))


# --------------------------------------------------------------------------- TOML loading


def _get(table: dict, dotted: str, path: Path):
    cur = table
    for part in dotted.split("."):
        if not isinstance(cur, dict) or part not in cur:
            raise ValueError(f"{path}: missing key '{dotted}'")
        cur = cur[part]
    return cur


def _num(table: dict, dotted: str, path: Path, positive: bool = True) -> float:
    v = _get(table, dotted, path)
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError(f"{path}: key '{dotted}' must be a number, got {v!r}")
    v = float(v)
    if positive and not v > 0.0:
        raise ValueError(f"{path}: key '{dotted}' must be > 0, got {v}")
    return v


def load_lander(path: str | Path) -> LanderModel:
    """Read a lander asset (TOML, SI units, body frame B) into a :class:`LanderModel`.

    Expected tables/keys (see ``assets/landers/mer_drop_lander.toml``): ``[lander]`` name,
    height_m, base_side_m, cm_height_m, mass_kg, inertia_kgm2 (3x3, symmetric positive
    definite); ``[airbags]`` bags (= 4), lobes_per_bag (= 6), lobe_diameter_m, lobe_spacing_m,
    standoff_m (> -lobe radius), pressure_pa, gas_volume_m3, gamma, damping_pa_s_per_m, friction;
    ``[chamber]`` ambient_pressure_pa; ``[instruments]`` name = [x, y, z] lever arms [m].

    Raises ``FileNotFoundError`` if the file is missing and ``ValueError`` naming the file and
    the key for malformed TOML, missing keys or bad values.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"lander asset not found: {path}")
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: invalid TOML: {exc}") from exc

    name = str(_get(data, "lander.name", path))
    height = _num(data, "lander.height_m", path)
    base_side = _num(data, "lander.base_side_m", path)
    cm_height = _num(data, "lander.cm_height_m", path)
    if not cm_height < height:
        raise ValueError(f"{path}: key 'lander.cm_height_m' ({cm_height}) must be below 'lander.height_m'")
    mass = _num(data, "lander.mass_kg", path)
    try:
        inertia = np.array(_get(data, "lander.inertia_kgm2", path), dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: key 'lander.inertia_kgm2' must be a 3x3 array of numbers") from exc
    if inertia.shape != (3, 3):
        raise ValueError(f"{path}: key 'lander.inertia_kgm2' must be 3x3, got shape {inertia.shape}")
    if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0.0):
        raise ValueError(f"{path}: key 'lander.inertia_kgm2' must be symmetric positive definite")

    bags = int(_num(data, "airbags.bags", path))
    if bags != 4:
        raise ValueError(f"{path}: key 'airbags.bags' must be 4 (one per tetrahedron face), got {bags}")
    lobes_per_bag = int(_num(data, "airbags.lobes_per_bag", path))
    if lobes_per_bag != 6:
        raise ValueError(f"{path}: key 'airbags.lobes_per_bag' must be 6 (3-2-1 rack), got {lobes_per_bag}")
    lobe_radius = 0.5 * _num(data, "airbags.lobe_diameter_m", path)
    lobe_spacing = _num(data, "airbags.lobe_spacing_m", path)
    standoff = _num(data, "airbags.standoff_m", path, positive=False)
    if standoff <= -lobe_radius:
        # negative: the lobes wrap the lander (centres closer than one radius to the face)
        raise ValueError(f"{path}: key 'airbags.standoff_m' must be > -lobe radius, got {standoff}")

    instruments_raw = _get(data, "instruments", path)
    if not isinstance(instruments_raw, dict):
        raise ValueError(f"{path}: key 'instruments' must be a table")
    instruments: dict[str, np.ndarray] = {}
    for key, val in instruments_raw.items():
        try:
            arm = np.array(val, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: key 'instruments.{key}' must be [x, y, z] in metres") from exc
        if arm.shape != (3,):
            raise ValueError(f"{path}: key 'instruments.{key}' must be [x, y, z], got shape {arm.shape}")
        arm.setflags(write=False)
        instruments[str(key)] = arm

    body = tetrahedron_body(height, base_side, cm_height)
    centers, bag = airbag_lobes(body, lobe_radius, lobe_spacing, standoff, lobes_per_bag)
    for arr in (inertia, centers, bag):
        arr.setflags(write=False)
    return LanderModel(
        name=name,
        mass=mass,
        inertia_B=inertia,
        body=body,
        lobe_centers_B=centers,
        lobe_radius=lobe_radius,
        lobe_bag=bag,
        pressure_pa=_num(data, "airbags.pressure_pa", path),
        gas_volume_m3=_num(data, "airbags.gas_volume_m3", path),
        gamma=_num(data, "airbags.gamma", path),
        damping=_num(data, "airbags.damping_pa_s_per_m", path, positive=False),
        friction=_num(data, "airbags.friction", path, positive=False),
        standoff=standoff,
        ambient_pressure_pa=_num(data, "chamber.ambient_pressure_pa", path, positive=False),
        instruments=instruments,
    )
