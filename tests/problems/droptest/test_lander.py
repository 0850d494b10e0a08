"""Tests of workbench.problems.droptest.lander against hand-derived geometry of the MER drop-test lander."""

import re
import tomllib
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

from workbench.problems.droptest.lander import (
    FACE_NAMES,
    airbag_lobes,
    airbag_mesh,
    load_lander,
    lobe_meshes,
    tetrahedron_body,
)

ASSET = Path(__file__).resolve().parents[3] / "assets" / "landers" / "mer_drop_lander.toml"

H, S, CM = 1.2, 1.6, 0.4  # REDLand: 1.2 m tall, 1.6 m base side; asset CM height 0.40 m


def _face_normals(mesh):
    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True), tri.mean(axis=1)


def test_tetrahedron_dimensions():
    body = tetrahedron_body(H, S, CM)
    V = body.vertices
    assert V.shape == (4, 3) and body.faces.shape == (4, 3)
    assert V[:, 2].min() == pytest.approx(-CM)  # base plane
    assert V[:, 2].max() == pytest.approx(H - CM)  # apex
    assert V[:, 2].max() - V[:, 2].min() == pytest.approx(1.2)
    base = V[np.isclose(V[:, 2], -CM)]
    assert base.shape == (3, 3)
    for a, b in combinations(base, 2):
        assert np.linalg.norm(a - b) == pytest.approx(1.6)
    # base centred on the axis, apex on the axis
    assert np.allclose(base.mean(axis=0)[:2], 0.0)
    apex = V[np.argmax(V[:, 2])]
    assert np.allclose(apex[:2], 0.0)
    # the PYBP edge: the base edge whose midpoint is on +Y, at the inradius s / (2 sqrt 3) = 0.46188 m
    mids = [(a + b) / 2 for a, b in combinations(base, 2)]
    on_y = [m for m in mids if abs(m[0]) < 1e-12 and m[1] > 0]
    assert len(on_y) == 1
    assert on_y[0][1] == pytest.approx(0.4618802154)
    # volume = (1/3) (sqrt3/4 s^2) h = 0.443405 m^3
    assert body.volume == pytest.approx(0.4434050067, rel=1e-9)
    # the origin is the CM only by construction; check the cm height enters as the base offset
    b2 = tetrahedron_body(H, S, 0.3)
    assert b2.vertices[:, 2].min() == pytest.approx(-0.3)


def test_tetrahedron_watertight_outward():
    body = tetrahedron_body(H, S, CM)
    assert body.is_watertight and body.is_winding_consistent
    n, c = _face_normals(body)
    assert np.all(np.einsum("ij,ij->i", n, c) > 0)  # origin (CM) inside, normals point away
    assert np.allclose(body.face_normals, n)
    # base face first, normal -Z; +Y side face normal ∝ (0, H, r_in) (hand: plane through the
    # edge y = r_in, z = -CM and the apex (0, 0, H - CM))
    assert FACE_NAMES[0] == "base" and np.allclose(n[0], [0, 0, -1])
    r_in = S / (2 * np.sqrt(3))
    expected = np.array([0.0, H, r_in]) / np.hypot(H, r_in)
    assert np.allclose(n[FACE_NAMES.index("side_PY")], expected)


def test_tetrahedron_rejects_bad_dimensions():
    with pytest.raises(ValueError):
        tetrahedron_body(1.2, 1.6, 1.3)
    with pytest.raises(ValueError):
        tetrahedron_body(-1.0, 1.6, 0.4)


def test_airbag_lobes_rack_geometry():
    body = tetrahedron_body(H, S, CM)
    r, a, so = 1.0, 1.55, 0.05
    centers, bag = airbag_lobes(body, r, a, so)
    assert centers.shape == (24, 3) and bag.shape == (24,)
    assert np.array_equal(np.bincount(bag), [6, 6, 6, 6])
    n, c = _face_normals(body)
    for k in range(4):
        ck = centers[bag == k]
        # every lobe centre is r + standoff outward from its face plane (a plane parallel to it)
        assert np.allclose((ck - body.vertices[body.faces[k, 0]]) @ n[k], r + so)
        # rack centred on the face centroid
        assert np.allclose(ck.mean(axis=0), c[k] + (r + so) * n[k])
        # billiard rack 3-2-1: nearest neighbours at the spacing, 9 touching pairs, corners 2a apart
        dists = np.array([np.linalg.norm(p - q) for p, q in combinations(ck, 2)])
        assert dists.min() == pytest.approx(a)
        assert np.sum(np.isclose(dists, a)) == 9
        assert dists.max() == pytest.approx(2 * a)
    # base rack oriented like the base face: single lobe toward the -Y vertex at (2/3)(sqrt3 a)
    base = centers[bag == 0]
    tip = base[np.argmin(base[:, 1])]
    assert np.allclose(tip, [0.0, -(2 / 3) * np.sqrt(3) * a, -CM - r - so])
    # and its row of three is parallel to the PYBP (X-directed) edge, on the +Y side
    row = base[np.isclose(base[:, 1], base[:, 1].max())]
    assert row.shape[0] == 3 and np.allclose(row[:, 2], -CM - r - so)


def test_load_lander_asset():
    m = load_lander(ASSET)
    raw = tomllib.loads(ASSET.read_text())  # engineering values may be retuned: compare to the file
    lb, ab = raw["lander"], raw["airbags"]
    assert m.mass == lb["mass_kg"] and m.lobe_radius == 0.5 * ab["lobe_diameter_m"] == 1.0
    assert m.standoff == ab["standoff_m"] and m.pressure_pa == ab["pressure_pa"]
    assert m.ambient_pressure_pa == raw["chamber"]["ambient_pressure_pa"]
    assert m.damping == ab["damping_pa_s_per_m"] and m.friction == ab["friction"]
    assert m.gamma == ab["gamma"] and m.gas_volume_m3 == ab["gas_volume_m3"]
    assert np.allclose(m.inertia_B, lb["inertia_kgm2"])
    assert np.allclose(m.instruments["PYBP"], raw["instruments"]["PYBP"])
    assert m.instruments["PYBP"][1] > 0 and abs(m.instruments["PYBP"][0]) < 1e-12  # on the +Y edge side
    # lobes sit lobe_radius + standoff off their faces
    n, c = _face_normals(m.body)
    h = np.einsum("ij,ij->i", m.lobe_centers_B - c[m.lobe_bag], n[m.lobe_bag])
    assert np.allclose(h, m.lobe_radius + m.standoff)
    assert set(m.instruments) == {"BP", "PYBP", "PXBP", "MXBP", "gyro"}
    assert m.lobe_centers_B.shape == (24, 3)
    assert np.allclose(m.body.vertices, tetrahedron_body(1.2, 1.6, 0.4).vertices)
    # every instrument sits inside the rigid body (behind every face plane)
    for arm in m.instruments.values():
        assert np.all(np.einsum("ij,ij->i", arm - c, n) < 0)
    # display meshes
    per_bag = lobe_meshes(m, subdivisions=1)
    assert len(per_bag) == 4
    mesh = airbag_mesh(m, subdivisions=1)
    assert len(mesh.vertices) == 24 * 42
    # every display vertex of bag 0 lies on the sphere (radius 1 m) of one of that bag's lobes
    r = np.linalg.norm(per_bag[0].vertices[:, None] - m.lobe_centers_B[m.lobe_bag == 0][None], axis=-1)
    assert np.all(np.any(np.isclose(r, 1.0), axis=1))


def test_load_lander_errors_name_file_and_key(tmp_path):
    text = ASSET.read_text()
    bad = tmp_path / "no_mass.toml"
    bad.write_text(re.sub(r"^mass_kg\s*=.*$", "", text, flags=re.M))
    with pytest.raises(ValueError, match=r"no_mass\.toml.*lander\.mass_kg.*missing"):
        load_lander(bad)
    typo = tmp_path / "typo.toml"
    typo.write_text(text.replace("mass_kg =", "massx_kg ="))
    with pytest.raises(ValueError, match=r"typo\.toml.*lander\.massx_kg.*did you mean 'mass_kg'"):
        load_lander(typo)
    bad2 = tmp_path / "bad_arm.toml"
    bad2.write_text(re.sub(r"^gyro\s*=.*$", "gyro = [0.0, -0.30]", text, flags=re.M))
    with pytest.raises(ValueError, match=r"bad_arm\.toml.*instruments\.gyro"):
        load_lander(bad2)
    with pytest.raises(ValueError, match=r"nope\.toml: file not found"):  # a ScenarioError
        load_lander(tmp_path / "nope.toml")
    bad4 = tmp_path / "deep.toml"
    bad4.write_text(re.sub(r"^standoff_m\s*=.*$", "standoff_m = -1.5", text, flags=re.M))
    with pytest.raises(ValueError, match=r"deep\.toml.*airbags\.standoff_m"):
        load_lander(bad4)
    bad3 = tmp_path / "broken.toml"
    bad3.write_text("[lander\n")
    with pytest.raises(ValueError, match=r"broken\.toml"):
        load_lander(bad3)
