"""The rigid lander body and its airbag lobes: a tetrahedron with a "billiard rack" on each face.

Provides :class:`LanderModel` (mass properties, body mesh, airbag lobes, instrument lever arms),
:func:`load_lander` (reads the TOML asset, e.g. ``assets/landers/mer_drop_lander.toml``),
:func:`tetrahedron_body`, :func:`airbag_lobes`, :func:`airbag_mesh` and :func:`lobe_meshes`.

Geometry follows the REDLand paper [1], "Test article and equipment": the closed MER drop-test
lander is 1.2 m tall with 1.6 m base sides (so it is *not* a regular tetrahedron); each face
carries one airbag of six 2 m lobes in a "billiard rack" (rows of 3, 2, 1).

Lander frame L and body frame B.  The asset describes the rig in its own lander frame L: any
orientation, any origin.  Either the shipped MER layout (``height_m``, ``base_side_m``,
``cm_height_m``: +Z from the base petal toward the apex, the base an equilateral triangle in the
plane ``z = -cm_height`` whose +Y edge (the one carrying the PYBP accelerometer triad, REDLand
Fig. 4-5) has its midpoint on the +Y axis, origin on the axis ``cm_height`` above the base), or the
four vertices ``vertices_m`` in L; ``cm_m`` the centre of mass (CM) in L (default: L's origin).
Instrument lever arms, the inertia (about the CM) and every other body-fixed vector of the scenario
are written in L.  The filter's body frame B has L's axes and its origin at the CM: ``x_B = x_L −
cm_L``; :class:`LanderModel` holds everything in B and keeps ``cm_L`` to convert other L vectors.

Face / bag order (index into ``body.faces`` and ``LanderModel.lobe_bag``): see :data:`FACE_NAMES`.
Each face is stored ``[a, b, c]`` with outward (counter-clockwise seen from outside) winding, and
``c`` is the face's "opposite" vertex: the apex for side faces, the -Y base vertex for the base.

[1] JPL, REDLand (Reconstruction of Entry, Descent and Landing) paper on the MER airbag drop
    tests at the SPF, 2001 test series, section "Test article and equipment".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, read_toml

__all__ = [
    "FACE_NAMES",
    "LANDER_SCHEMA",
    "LanderModel",
    "SIMULATOR_KEYS",
    "load_lander",
    "require_simulator_keys",
    "tetrahedron_body",
    "tetrahedron_from_vertices",
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
        (These five and ``ambient_pressure_pa`` are read by the truth simulator only: None when the
        asset leaves them out, as user data may; :data:`SIMULATOR_KEYS`.)
        standoff: gap between a lobe's inner surface and its lander face [m]; negative when the
            lobes wrap the lander (centre closer than one radius to the face), > -lobe_radius.
        ambient_pressure_pa: chamber (or atmosphere) pressure [Pa].
        instruments: lever arms of the sensors from the CM in B, name -> (3,) [m].
        cm_L: the CM in the asset's lander frame L (3,) [m]; a vector ``x_L`` written in L is
            ``x_L − cm_L`` in B (same axes).
        contact_stiffness: stiffness [N/m] of the rigid lander against the surface where a vertex
            strikes it (structure and ramp compliance): the truth simulator's body contact, and how
            deep a full stroke's vertex may reach under the measured peak load (health checks).
    """

    name: str
    mass: float
    inertia_B: np.ndarray
    body: trimesh.Trimesh
    lobe_centers_B: np.ndarray
    lobe_radius: float
    lobe_bag: np.ndarray
    pressure_pa: float | None
    gas_volume_m3: float | None
    gamma: float | None
    damping: float | None
    friction: float | None
    standoff: float
    ambient_pressure_pa: float | None
    instruments: dict[str, np.ndarray] = field(default_factory=dict)
    cm_L: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact_stiffness: float = 2.0e7

    def to_body(self, x_L) -> np.ndarray:
        """A point given in the lander frame L (3,) or (n, 3) [m] -> body frame B (from the CM) [m]."""
        return np.asarray(x_L, float) - self.cm_L


def tetrahedron_from_vertices(vertices: np.ndarray, origin: np.ndarray | None = None) -> trimesh.Trimesh:
    """Tetrahedral body from its four vertices (4, 3) [m]: 0, 1, 2 the base, 3 the apex, in the
    vertex order of :func:`tetrahedron_body` (side face ``side_PY`` is the one opposite vertex 0,
    ``side_PX`` opposite vertex 2, ``side_MX`` opposite vertex 1).  Faces in the order of
    :data:`FACE_NAMES`, wound outward about the tetrahedron's centroid, last vertex of each face the
    one opposite its "rack base" edge.  ``origin`` (3,) (default: the centroid) must lie strictly
    inside.  Raises ``ValueError`` for a degenerate tetrahedron (volume below 1e-9 m³)."""
    V = np.asarray(vertices, float)
    if V.shape != (4, 3) or not np.all(np.isfinite(V)):
        raise ValueError(f"tetrahedron: need 4 finite vertices [x, y, z], got shape {V.shape}")
    vol = abs(np.linalg.det(V[1:] - V[0])) / 6.0
    if vol < 1e-9:
        raise ValueError(f"tetrahedron: the four vertices are (nearly) coplanar (volume {vol:.2e} m³)")
    faces = np.array([[2, 1, 0], [1, 2, 3], [0, 1, 3], [2, 0, 3]])
    centre = V.mean(axis=0)
    tri = V[faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", nrm, tri.mean(axis=1) - centre) < 0.0
    faces[flip] = faces[flip][:, [1, 0, 2]]
    if origin is not None:
        tri = V[faces]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        if np.any(np.einsum("ij,ij->i", nrm, np.asarray(origin, float) - tri[:, 0]) >= 0.0):
            raise ValueError("tetrahedron: the centre of mass is not inside the body")
    return trimesh.Trimesh(vertices=V, faces=faces, process=False)


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
    lobe_spacing: float | np.ndarray,
    standoff: float | np.ndarray,
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

    ``lobe_spacing`` and ``standoff`` are one value for every face or one per face (face order).
    Returns ``(centers (n_faces*6, 3) [m], bag_index (n_faces*6,) int)``, lobes grouped by face
    in face order.  Only ``lobes_per_bag == 6`` (the MER rack) is supported.
    """
    if int(lobes_per_bag) != 6:
        raise ValueError(f"airbag_lobes: only the 3-2-1 rack (6 lobes per bag) is supported, got {lobes_per_bag}")
    V = np.asarray(body.vertices, dtype=float)
    F = np.asarray(body.faces, dtype=int)
    spacing = np.broadcast_to(np.asarray(lobe_spacing, float), (len(F),))
    stand = np.broadcast_to(np.asarray(standoff, float), (len(F),))
    centers = []
    bag = []
    for k, (ia, ib, ic) in enumerate(F):
        offsets = _rack_offsets(spacing[k])
        a, b, c = V[ia], V[ib], V[ic]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        ex = (b - a) / np.linalg.norm(b - a)
        ey = np.cross(n, ex)  # in-plane, perpendicular to a-b
        if np.dot(ey, c - a) < 0.0:
            ey = -ey
        origin = (a + b + c) / 3.0 + (float(lobe_radius) + float(stand[k])) * n
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


# --------------------------------------------------------------------------- reading the asset

#: What the meaning of a key only the truth simulator reads says (:data:`SIMULATOR_KEYS`).
_SIM_ONLY = " (truth simulator only: required by a synthetic scenario, optional for user data)"

#: The lander asset's keys only the truth simulator reads (the gas, the fabric, the chamber):
#: :func:`require_simulator_keys` requires them for a synthetic scenario; user data may leave them out.
SIMULATOR_KEYS = (
    ("airbags.pressure_pa", "pressure_pa"),
    ("airbags.gas_volume_m3", "gas_volume_m3"),
    ("airbags.gamma", "gamma"),
    ("airbags.damping_pa_s_per_m", "damping"),
    ("airbags.friction", "friction"),
    ("chamber.ambient_pressure_pa", "ambient_pressure_pa"),
)

#: The lander asset (``[vehicle] lander``, e.g. ``assets/landers/mer_drop_lander.toml``), read by
#: :func:`load_lander` (listed with the drop test's other schemas in :mod:`.config`).  Cross-field
#: rules stay there as code (the layout given one way or the other, ``cm_height_m < height_m``, the
#: inertia symmetric positive definite, ``standoff_m`` above minus the lobe radius, one face per lobe).
LANDER_SCHEMA = Schema(
    "lander",
    "drop-test lander asset",
    (
        Table(
            "lander",
            "the rigid lander in its own lander frame L",
            (
                Key("name", "str", REQUIRED, meaning="human-readable name"),
                Key("mass_kg", "float", REQUIRED, "kg", "total mass", gt=0.0),
                Key(
                    "inertia_kgm2",
                    "list",
                    REQUIRED,
                    "kg m²",
                    "3 × 3 inertia about the CM, in L's axes; symmetric positive definite",
                ),
                Key(
                    "vertices_m",
                    "list",
                    None,
                    "m",
                    "4 × [x, y, z]: the tetrahedron in L, base vertices 0, 1, 2, then the apex 3. The side face "
                    "opposite vertex 0 is `side_PY`, opposite 2 `side_PX`, opposite 1 `side_MX` (the bag names)",
                ),
                Key(
                    "cm_m",
                    "vec3",
                    None,
                    "m",
                    "the centre of mass in L; required with `vertices_m`, must lie inside the body; absent: L's origin",
                ),
                Key(
                    "contact_stiffness_n_per_m",
                    "float",
                    2.0e7,
                    "N/m",
                    "stiffness of the rigid lander against the ramp where a vertex strikes it in a full stroke "
                    "(the structure's and the ramp's compliance; the default: an aluminium frame on the ramp "
                    "[engineering]): the truth simulator's body contact, and the depth m·|f|max/k a full "
                    "stroke's vertex may reach under the measured peak load in the `max_stroke.clearance` check",
                    gt=0.0,
                ),
                Key(
                    "height_m",
                    "float",
                    None,
                    "m",
                    "instead of `vertices_m`, the MER layout: closed height (+Z towards the apex, a base-edge "
                    "midpoint on +Y, L's origin on the axis `cm_height_m` above the base)",
                    gt=0.0,
                ),
                Key("base_side_m", "float", None, "m", "MER layout: side of the equilateral base", gt=0.0),
                Key("cm_height_m", "float", None, "m", "MER layout: CM above the base, below `height_m`", gt=0.0),
            ),
        ),
        Table(
            "airbags",
            "the four airbags (one per face) and their gas",
            (
                Key("bags", "int", REQUIRED, meaning="number of bags: 4 (one per tetrahedron face)", ge=4, le=4),
                Key("lobe_diameter_m", "float", REQUIRED, "m", "lobe sphere diameter", gt=0.0),
                Key(
                    "lobes_per_bag",
                    "int",
                    None,
                    meaning="the 3-2-1 'billiard rack': 6 (required unless `lobe_centers_m` is given)",
                    ge=6,
                    le=6,
                ),
                Key(
                    "lobe_spacing_m",
                    "number_or_list",
                    None,
                    "m",
                    "rack: lobe centre spacing, one number for every face or one per face in bag order `base, "
                    "side_PY, side_PX, side_MX` (required with the rack)",
                    gt=0.0,
                ),
                Key(
                    "standoff_m",
                    "number_or_list",
                    None,
                    "m",
                    "the gap from the lander face's plane to the nearest point of each lobe sphere of its rack, "
                    "along the face's outward normal: the rack's centroid sits `lobe_diameter_m`/2 + "
                    "`standoff_m` off the face centroid. Must be > −lobe radius; negative = the spheres cut the "
                    "face plane (lobes wrapping the lander: the MER asset's −0.6 puts the centres 0.4 m off the "
                    "face). One number or one per face as `lobe_spacing_m` (required with the rack; with "
                    "`lobe_centers_m` only reported, absent = 0)",
                ),
                Key(
                    "lobe_centers_m",
                    "list",
                    None,
                    "m",
                    "instead of the rack: n × [x, y, z], every lobe centre in L",
                ),
                Key(
                    "lobe_faces",
                    "list",
                    None,
                    meaning='with `lobe_centers_m`: the face of each lobe (`"base"`, `"side_PY"`, … or 0–3)',
                ),
                Key(
                    "pressure_pa",
                    "float",
                    None,
                    "Pa",
                    "initial absolute inflation pressure" + _SIM_ONLY + "; with user data, when given (with "
                    "`[chamber] ambient_pressure_pa`), it sets how far the `geometry.first_contact` check lets "
                    "the lobes press in at the measured first touch (absent: up to a lobe radius)",
                    gt=0.0,
                ),
                Key("gas_volume_m3", "float", None, "m³", "shared gas volume of the vented bags" + _SIM_ONLY, gt=0.0),
                Key("gamma", "float", None, "1", "ratio of specific heats of the inflation gas" + _SIM_ONLY, gt=0.0),
                Key(
                    "damping_pa_s_per_m",
                    "float",
                    None,
                    "Pa s/m",
                    "fabric/venting damping, pressure-equivalent per m/s of penetration rate" + _SIM_ONLY,
                ),
                Key("friction", "float", None, "1", "Coulomb friction coefficient airbag/ramp" + _SIM_ONLY),
            ),
        ),
        Table(
            "chamber",
            "the test chamber",
            (
                Key(
                    "ambient_pressure_pa",
                    "float",
                    None,
                    "Pa",
                    "chamber pressure" + _SIM_ONLY + "; with user data as `[airbags] pressure_pa`",
                ),
            ),
        ),
        Table(
            "instruments",
            "sensor positions (required table)",
            free="vec3",
            free_meaning="sensor position in L [m]: accelerometer triads by name, `gyro`",
        ),
    ),
    noun="lander asset",
    intro="Keys of a drop-test lander asset (`[vehicle] lander`)",
)


def require_simulator_keys(model: LanderModel, path: Path, *, except_pressure: bool = False) -> None:
    """:class:`ScenarioError` naming the lander asset ``path`` and the first key of
    :data:`SIMULATOR_KEYS` that ``model`` lacks: the truth simulator needs them all (a synthetic
    scenario); ``except_pressure``: the bag pressure comes from elsewhere (``[synthetic]
    bag_pressure_psi``)."""
    for key, attr in SIMULATOR_KEYS:
        if getattr(model, attr) is None and not (except_pressure and attr == "pressure_pa"):
            raise ScenarioError(
                path, key, "missing: the truth simulator of a synthetic scenario needs it (user data may omit it)"
            )


def _per_face(v: float | list, key: str, path: Path) -> np.ndarray:
    """A per-face value as the schema returned it (one number for every face, or a list) -> (4,)."""
    if isinstance(v, float):
        v = [v]
    if len(v) == 1:
        v = v * len(FACE_NAMES)
    if len(v) != len(FACE_NAMES) or any(isinstance(x, bool) or not isinstance(x, int | float) for x in v):
        raise ScenarioError(path, key, f"must be a number or one per face ({', '.join(FACE_NAMES)})")
    return np.array(v, dtype=float)


def _matrix(v, key: str, path: Path, shape: tuple[int, ...], what: str) -> np.ndarray:
    try:
        a = np.array(v, dtype=float)
    except (TypeError, ValueError):
        raise ScenarioError(path, key, f"must be {what}") from None
    if (shape and a.shape != shape) or not np.all(np.isfinite(a)):
        raise ScenarioError(path, key, f"must be {what}, got {v!r}"[:300])
    return a


def load_lander(path: str | Path) -> LanderModel:
    """Read a lander asset (TOML, lengths in m, the lander frame L) into a :class:`LanderModel`
    (everything in B: L's axes, origin at the CM).

    The keys, their types, defaults and bounds are :data:`LANDER_SCHEMA`
    (FORMATS.md, "Drop-test lander asset and setup file"); the rules between keys are checked here:
    either ``vertices_m`` (with ``cm_m``) or the MER layout ``height_m``, ``base_side_m``,
    ``cm_height_m`` (``cm_height_m < height_m``); the inertia symmetric positive definite; either the
    3-2-1 rack (``lobes_per_bag``, ``lobe_spacing_m``, ``standoff_m`` > −lobe radius) or
    ``lobe_centers_m`` with ``lobe_faces``.  Every error (missing file, invalid TOML, unknown key with
    a "did you mean", out-of-range value) is a :class:`ScenarioError` naming the file and the key.
    """
    path = Path(path)
    raw = read_toml(path)
    data = LANDER_SCHEMA.validate(raw, path)
    if "instruments" not in raw:
        raise ScenarioError(path, "instruments", "missing (required table of a lander asset)")
    lt, at = data["lander"], data["airbags"]

    legacy = [k for k in ("height_m", "base_side_m", "cm_height_m") if lt[k] is not None]
    if lt["vertices_m"] is not None:
        if legacy:
            raise ScenarioError(
                path,
                "lander.vertices_m",
                f"give either 'vertices_m' (any frame) or {legacy} (the MER layout), not both",
            )
        if lt["cm_m"] is None:
            raise ScenarioError(path, "lander.cm_m", "required with 'lander.vertices_m' (the CM in that frame)")
        vertices_L = _matrix(lt["vertices_m"], "lander.vertices_m", path, (4, 3), "4 finite [x, y, z] vertices [m]")
    else:
        for k in ("height_m", "base_side_m", "cm_height_m"):
            if lt[k] is None:
                raise ScenarioError(path, f"lander.{k}", "missing (the MER layout; or give 'vertices_m' and 'cm_m')")
        if not lt["cm_height_m"] < lt["height_m"]:
            raise ScenarioError(path, "lander.cm_height_m", f"{lt['cm_height_m']} must be below 'lander.height_m'")
        vertices_L = np.asarray(tetrahedron_body(lt["height_m"], lt["base_side_m"], lt["cm_height_m"]).vertices, float)
    cm_L = np.array(lt["cm_m"], float) if lt["cm_m"] is not None else np.zeros(3)
    try:
        body = tetrahedron_from_vertices(vertices_L - cm_L, origin=np.zeros(3))
    except ValueError as exc:
        raise ScenarioError(path, "lander.vertices_m", f"(with 'lander.cm_m'): {exc}") from exc
    inertia = _matrix(lt["inertia_kgm2"], "lander.inertia_kgm2", path, (3, 3), "a 3x3 array of numbers [kg m²]")
    if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0.0):
        raise ScenarioError(path, "lander.inertia_kgm2", "must be symmetric positive definite")

    lobe_radius = 0.5 * at["lobe_diameter_m"]
    if at["lobe_centers_m"] is not None:  # an explicit lobe layout, any number of lobes per face
        cen = _matrix(at["lobe_centers_m"], "airbags.lobe_centers_m", path, (), "a list of [x, y, z] in L")
        if cen.ndim != 2 or cen.shape[1] != 3:
            raise ScenarioError(path, "airbags.lobe_centers_m", "must be a list of [x, y, z] in the lander frame")
        try:
            faces_raw = at["lobe_faces"] or []
            bag = np.array([FACE_NAMES.index(f) if isinstance(f, str) else int(f) for f in faces_raw], dtype=int)
        except (TypeError, ValueError) as exc:
            raise ScenarioError(
                path, "airbags.lobe_faces", f"must list, per lobe, its face ({', '.join(FACE_NAMES)} or 0-3)"
            ) from exc
        if bag.shape != (cen.shape[0],) or np.any((bag < 0) | (bag > 3)) or len(set(bag.tolist())) != 4:
            raise ScenarioError(
                path,
                "airbags.lobe_faces",
                f"needs one face per lobe of 'lobe_centers_m' ({cen.shape[0]}), each face 0-3 used at least once",
            )
        centers = cen - cm_L
        st = at["standoff_m"]
        standoff = st if isinstance(st, float) else float(st[0]) if st is not None and len(st) == 1 else 0.0
    else:
        for k in ("lobes_per_bag", "lobe_spacing_m", "standoff_m"):
            if at[k] is None:
                raise ScenarioError(path, f"airbags.{k}", "missing (the 3-2-1 rack; or give 'lobe_centers_m')")
        lobe_spacing = _per_face(at["lobe_spacing_m"], "airbags.lobe_spacing_m", path)
        standoffs = _per_face(at["standoff_m"], "airbags.standoff_m", path)
        if np.any(standoffs <= -lobe_radius):
            # negative: the lobes wrap the lander (centres closer than one radius to the face)
            raise ScenarioError(
                path, "airbags.standoff_m", f"must be > -lobe radius ({-lobe_radius:g} m), got {standoffs}"
            )
        centers, bag = airbag_lobes(body, lobe_radius, lobe_spacing, standoffs, at["lobes_per_bag"])
        standoff = float(standoffs[0]) if np.all(standoffs == standoffs[0]) else float(np.min(standoffs))

    instruments: dict[str, np.ndarray] = {}
    for key, arm in data["instruments"].items():
        arm = np.asarray(arm, float) - cm_L
        arm.setflags(write=False)
        instruments[str(key)] = arm

    for arr in (inertia, centers, bag, cm_L):
        arr.setflags(write=False)
    return LanderModel(
        name=lt["name"],
        mass=lt["mass_kg"],
        inertia_B=inertia,
        body=body,
        lobe_centers_B=centers,
        lobe_radius=lobe_radius,
        lobe_bag=bag,
        pressure_pa=at["pressure_pa"],
        gas_volume_m3=at["gas_volume_m3"],
        gamma=at["gamma"],
        damping=at["damping_pa_s_per_m"],
        friction=at["friction"],
        standoff=standoff,
        ambient_pressure_pa=data["chamber"]["ambient_pressure_pa"],
        instruments=instruments,
        cm_L=cm_L,
        contact_stiffness=float(lt["contact_stiffness_n_per_m"]),
    )
