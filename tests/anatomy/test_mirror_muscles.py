"""Muscles built as mirror images (issue 25, a symmetric rig for a symmetric head).

The template skull is its own mirror image about x = 0, vertex for vertex (since issue 25:
its left half mirrored, ``tools/build_template.py``). With ``mirror`` the right twins are
mirror images of the left ones (up to the midline mentalis, where a twin's line lies on it),
contract as mirror images, the orbicularis oris pairs its samples k and -k, and a midline
sheet (the mentalis) is its own mirror image.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from faceforge.anatomy.layers import MusculoskeletalSystem
from faceforge.anatomy.muscles.build import build_muscles_on
from faceforge.anatomy.muscles.muscle_map import load_muscle_map
from faceforge.anatomy.skull import load_skull
from faceforge.geometry.mirror import Mirror

ROOT = Path(__file__).resolve().parents[2]
MIRROR = Mirror((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def built():
    """(skull, mirrored system, plain {name: rest positions}): the map built with the mirror;
    without it, the template's own muscles (disk-cached, :func:`faceforge.fit.template.load_template`)."""
    from faceforge.fit.template import load_template

    skull = load_skull(ROOT / "templates" / "skull")
    specs = load_muscle_map(ROOT / "templates" / "muscle_map.yaml", skull)
    cfg = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())["muscle"]
    stiffness = {kind: cfg[kind]["stiffness"] for kind in ("linear", "sphincter")}
    muscles = build_muscles_on(specs, skull.cranium, skull.mandible, skull.diagonal, stiffness, mirror=MIRROR)
    plain = {m[0]: m[1] for m in load_template(ROOT / "templates" / "skull", ROOT / "templates" / "muscle_map.yaml").muscles}
    return skull, MusculoskeletalSystem.from_parts(skull.cranium, skull.mandible, muscles), plain


def _gap(rest, left, diagonal):
    pl, pr = rest(left), rest(left[:-2] + "_R")
    return np.linalg.norm(MIRROR(pl) - pr, axis=1).max() / diagonal


def test_template_bone_is_its_own_mirror_image(built):
    from faceforge.geometry.mirror_mesh import vertex_partners

    skull = built[0]
    for v, f in (skull.cranium, skull.mandible):
        partner = vertex_partners(v)
        assert partner is not None
        # the mirror-image triangulation: each face's partner vertices form a face
        faces = {tuple(sorted(x)) for x in np.asarray(f).tolist()}
        assert all(tuple(sorted(x)) in faces for x in partner[np.asarray(f)].tolist())


def test_right_twins_are_the_mirror_images_of_the_left(built):
    skull, mirrored, plain = built
    lefts = [n for n in mirrored.muscles if n.endswith("_L")]
    assert len(lefts) == 15
    for left in lefts:
        right = left[:-2] + "_R"
        np.testing.assert_array_equal(mirrored.muscles[right].faces, mirrored.muscles[left].faces[:, ::-1])
        # exact on the bone and on mirrored twins; the depressor labii lies on the midline
        # mentalis too, whose grid mirrors but whose triangles' diagonals do not (closest points
        # on it: up to 0.5 mm since the mentalis inserts over the chin boss), the muscles above
        # it follow
        on_midline = left.startswith(("depressor_labii", "depressor_anguli", "risorius"))
        assert _gap(mirrored.rest_positions, left, skull.diagonal) < (2e-3 if on_midline else 1e-9), left
    m = mirrored.muscles["mentalis"]
    h, w = m.topology.h, m.topology.w
    for layer in (0, 1):   # column j mirrors column w - 1 - j
        grid = m.rest_positions[layer * h * w:(layer + 1) * h * w].reshape(h, w, 3)
        assert np.linalg.norm(MIRROR(grid) - grid[:, ::-1], axis=2).max() / skull.diagonal < 1e-4


def test_orbicularis_oris_samples_pair_up(built):
    skull, system, plain = built
    m = system.muscles["orbicularis_oris"]
    h, w = m.topology.h, m.topology.w
    bottom = m.rest_positions[: h * w].reshape(h, w, 3)
    pair = (-np.arange(h)) % h
    gap = np.linalg.norm(MIRROR(bottom) - bottom[pair], axis=2).max() / skull.diagonal
    assert gap < 1e-3
    top = m.rest_positions[h * w:].reshape(h, w, 3)   # the top sheet too (diagonal-independent normals)
    assert np.linalg.norm(MIRROR(top) - top[pair], axis=2).max() / skull.diagonal < 1e-3


def test_mirrored_rig_rests_and_contracts_as_mirror_images(built):
    skull, system, _ = built
    system.reset()
    rest, _ = system.world(rest=True)
    for _ in range(30):
        system.step({}, None)
    v, _ = system.world()
    assert np.abs(v - rest).max() <= 1e-9 * skull.diagonal   # the rest is still a fixed point
    for name in ("zygomaticus_major", "frontalis_inner", "levator_labii_outer"):
        moved = {}
        for side in ("_L", "_R"):
            system.reset()
            for _ in range(20):
                system.step({name + side: 0.6}, None)
            moved[side] = system.positions(name + side) - system.rest_positions(name + side)
        diff = np.linalg.norm(MIRROR.direction(moved["_L"]) - moved["_R"]) / np.linalg.norm(moved["_L"])
        assert diff < 0.05, (name, diff)
    system.reset()


def _groove():
    """A symmetric trough along y about x = 0: walls z = |x| (x in [-1, 1], y in [0, 1]), its
    bottom the midline; triangulated as its own mirror image."""
    v = np.array([[-1.0, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 1.0],
                  [-1.0, 1.0, 1.0], [0.0, 1.0, 0.0], [1.0, 1.0, 1.0]])
    f = np.array([[0, 1, 4], [0, 4, 3], [2, 5, 4], [2, 4, 1]])
    return v, f


def test_a_split_point_over_a_midline_groove_lands_on_the_plane():
    """Over a groove the closest points of a symmetric body to a point on the plane are two,
    left and right of it at equal distance, and which one the closest-point search returned was
    round-off (MakeHuman's maxilla under the nose: the orbicularis oris' outer loop split 0.45 mm
    right of the plane on an AVX-512 machine, its samples 0.8 mm off their mirror images, the
    levator labii pair 18 % apart). The split point is the closest point of the body's midline."""
    from faceforge.anatomy.muscles.mirror import _on_plane
    from faceforge.geometry.surface_points import SurfacePoints

    v, f = _groove()
    wall = SurfacePoints(np.array([2]), np.array([[0.25, 0.25, 0.5]]))   # (0.5, 0.75, 0.5) on a wall
    q = _on_plane(wall, [("mandible", (v, f))], v, f, MIRROR).positions(v, f)[0]
    assert abs(MIRROR.side(q)) < 1e-12
    np.testing.assert_allclose(q, [0.0, 0.75, 0.0], atol=1e-12)   # the bottom, under the foot (0, .75, .5)


def test_plane_section_closest_of_a_body_off_the_plane_is_none():
    from faceforge.anatomy.muscles.mirror import plane_section_closest

    v, f = _groove()
    assert plane_section_closest(np.zeros(3), v + [3.0, 0.0, 0.0], f, MIRROR) is None
    d, sp = plane_section_closest(np.array([0.0, 2.0, 0.0]), v, f, MIRROR)   # beyond the end: its corner
    assert d == pytest.approx(1.0) and sp.positions(v, f)[0] == pytest.approx([0.0, 1.0, 0.0])
