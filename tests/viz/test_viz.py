"""Headless pictures: shading, projection, muscle sheets, and the template picture."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import trimesh  # noqa: E402

from faceforge.viz.render import LIGHT, VIEWS, Layer, lambert, render_meshes, shaded_polygons  # noqa: E402
from faceforge.viz.template import grid_faces, muscle_layers, muscle_sheet, render_template, resample  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def sphere():
    m = trimesh.creation.icosphere(subdivisions=2)
    return np.asarray(m.vertices), np.asarray(m.faces)


def test_views_are_rotations_with_the_right_camera():
    for name, r in VIEWS.items():
        assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0), name
    assert np.allclose(VIEWS["front"][2], [0, 0, 1]), "front camera on +Z"
    assert np.allclose(VIEWS["side"][2], [1, 0, 0]), "side camera on the subject's left (+X)"
    assert np.allclose(VIEWS["side"][1], [0, 1, 0]) and np.allclose(VIEWS["front"][1], [0, 1, 0]), "Y up"


def test_lambert_range_and_two_sided():
    n = np.array([LIGHT, -LIGHT, [1.0, 0.0, 0.0]])
    s = lambert(n, ambient=0.3)
    assert np.isclose(s[0], 1.0)
    assert np.all((s >= 0.3) & (s <= 1.0))
    # a back face is lit like its flipped normal
    flipped = LIGHT * [1.0, 1.0, -1.0]
    assert np.isclose(lambert(-flipped[None])[0], lambert(flipped[None])[0])


def test_polygons_sorted_back_to_front_and_degenerates_dropped():
    v, f = sphere()
    bad = np.vstack([f, [[0, 0, 1]]])
    polys, rgba, depth, _ = shaded_polygons([Layer(v, bad)], "front")
    assert len(polys) == len(f)
    assert np.all(np.diff(depth) >= 0)
    assert rgba.shape == (len(f), 4) and np.all((rgba >= 0) & (rgba <= 1))
    # nearest triangle (last drawn) is at the front of the sphere
    assert depth[-1] > 0.9


def test_render_meshes_writes_a_non_blank_png(tmp_path):
    v, f = sphere()
    out = tmp_path / "s.png"
    render_meshes(out, [Layer(v, f, label="ball")], points=v[:3], size=2.0, dpi=60)
    img = matplotlib.image.imread(out)
    assert img.shape[0] > 50 and img.std() > 0.05


def test_resample_equal_steps_and_endpoints():
    line = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 3.0, 0]])
    r = resample(line, 5)
    assert np.allclose(r[0], line[0]) and np.allclose(r[-1], line[-1])
    steps = np.linalg.norm(np.diff(r, axis=0), axis=1)
    assert np.allclose(steps[[0, 2, 3]], 1.0)  # Eq. 3: total length 4, 4 steps
    loop = resample(np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 1.0, 0], [0.0, 1.0, 0]]), 8, closed=True)
    assert len(loop) == 8 and np.allclose(np.linalg.norm(np.diff(np.vstack([loop, loop[:1]]), axis=0), axis=1), 0.5)


def test_grid_faces_counts_and_orientation():
    f = grid_faces(5, 3)
    assert len(f) == 2 * 4 * 2 and f.max() == 14
    closed = grid_faces(6, 3, closed=True)
    assert len(closed) == 2 * 6 * 2
    # every interior edge is shared by two triangles running it in opposite directions
    half = np.concatenate([closed[:, [0, 1]], closed[:, [1, 2]], closed[:, [2, 0]]])
    assert len({tuple(e) for e in half.tolist()}) == len(half)


class _Spec:
    """Minimal stand-in with the MuscleSpec fields the sheet uses."""

    def __init__(self, active=True):
        self.type, self.h, self.w, self.active = "linear", 5, 3, active
        self.origin = np.array([[0.0, 0, 0], [2.0, 0, 0]])
        self.insertion = np.array([[0.0, 4.0, 0], [2.0, 4.0, 0]])

    def action_lines(self):
        return {"A0": np.vstack([self.origin[:1], self.insertion[:1]]), "A1": self.insertion,
                "A2": np.vstack([self.origin[-1:], self.insertion[-1:]]), "A3": self.origin}


def test_sheet_rest_matches_the_contour_and_contraction_follows_eq4():
    spec = _Spec()
    g = muscle_sheet(spec)
    assert g.shape == (5, 3, 3)
    assert np.allclose(g[0], resample(spec.origin, 3)) and np.allclose(g[-1], resample(spec.insertion, 3))
    c = 0.25
    gc = muscle_sheet(spec, c)
    assert np.allclose(gc[0], g[0]), "the origin is the fixed site"
    length = np.linalg.norm(gc[-1] - gc[0], axis=1)
    assert np.allclose(length, 4.0 * (1 - c)), "fibres shorten by the requested fraction"
    assert np.allclose(muscle_sheet(_Spec(active=False), 0.5), g), "passive tissue ignores contraction"


@pytest.fixture(scope="module")
def template():
    from faceforge.anatomy.muscles.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull

    skull = load_skull(ROOT / "templates" / "skull")
    return skull, load_muscle_map(ROOT / "templates" / "muscle_map.yaml", skull)


def test_jaw_moves_mandible_muscles_only(template):
    skull, muscles = template
    pick = [m for m in muscles if m.name in ("frontalis_inner_L", "mentalis", "orbicularis_oris")]
    rest = {l.label: l.vertices for l in muscle_layers(skull, pick)[2:]}
    opened = {l.label: l.vertices for l in muscle_layers(skull, pick, jaw=(0.26, 0.0, 0.0))[2:]}
    moved = {k: np.linalg.norm(opened[k] - rest[k], axis=1) for k in rest}
    assert moved["front in L"].max() == 0.0
    assert moved["mentalis"].min() > 0.5, "the chin muscle rides on the mandible"
    assert moved["orb oris"].max() > 0.3 and moved["orb oris"].min() < 1e-9, "spans both bones"


def test_render_template_headless(tmp_path, template):
    skull, muscles = template
    out = tmp_path / "muscles.png"
    pick = [m for m in muscles if m.layer == 0 or m.type == "sphincter"]
    render_template(skull, pick, out, jaw=(0.2, 0.0, 0.0), contractions={"mentalis": 0.5}, size=2.5, dpi=60)
    img = matplotlib.image.imread(out)
    assert img.std() > 0.05


def test_given_meshes_replace_the_proxy(template):
    skull, muscles = template
    pick = [m for m in muscles if m.name in ("mentalis", "risorius_L")]
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    layers = muscle_layers(skull, pick, meshes={"mentalis": (box.vertices, box.faces)})
    drawn = {l.label: l for l in layers[2:]}
    assert np.array_equal(drawn["mentalis"].vertices, box.vertices)
    assert len(drawn["risorius L"].vertices) != len(box.vertices)


def test_template_render_command_simulates_the_map(invoke, tmp_path):
    """`faceforge template render` end to end (it builds and steps the whole layered map with the
    config's muscle section, damping included): a PNG, and a one-line error for an unknown muscle."""
    out = tmp_path / "frown.png"
    ok = invoke("-w", tmp_path, "template", "render", "-o", out, "--frames", "2",
                "--contract", "corrugator_supercilii_L=0.5")
    assert ok.exit_code == 0, ok.stderr
    assert matplotlib.image.imread(out).std() > 0.05
    bad = invoke("-w", tmp_path, "template", "render", "-o", tmp_path / "x.png", "--contract", "nope=0.5")
    assert bad.exit_code == 2 and "unknown muscle(s) nope" in bad.stderr and len(bad.stderr.splitlines()) == 1


def test_smooth_sheet_with_heat_maps(tmp_path):
    """Smooth-shaded panels with a heat map beside each: a face region frames part of the
    mesh, and a vertex that moves shows in the heat map's colours."""
    import numpy as np
    from PIL import Image

    from faceforge.viz.contact_sheet import contact_sheet, face_region

    g = np.linspace(-1.0, 1.0, 21)
    x, y = np.meshgrid(g, g)
    v = np.stack([x.ravel(), y.ravel(), 0.3 * (1 - x.ravel() ** 2 - y.ravel() ** 2)], axis=1)
    f = []
    for i in range(20):
        for j in range(20):
            a = i * 21 + j
            f += [[a, a + 1, a + 22], [a, a + 22, a + 21]]
    f = np.asarray(f)
    moved = v.copy()
    moved[np.linalg.norm(v[:, :2], axis=1) < 0.3, 2] += 0.2
    lm = {"2.1": [0, -0.8, 0], "3.7": [0.4, 0.3, 0], "3.12": [-0.4, 0.3, 0]}
    region = face_region(v, lm)
    assert region is not None and 0 < region.sum() < len(v)
    out = contact_sheet(tmp_path / "s.png", np.stack([v, moved]), f, [0, 1], 1.0, cols=2,
                        heat=0.2, heat_label="0-0.2", region=region, labels=["rest", "moved"])
    img = np.asarray(Image.open(out).convert("RGB"), dtype=float)
    assert img.shape[1] >= 4 * 250
    hot = (img[:, :, 0] > 200) & (img[:, :, 1] > 200) & (img[:, :, 2] < 200)   # inferno's top: yellow
    assert hot.sum() > 50, "the moved patch shows in the heat map"


def _plane(lo: float, hi: float, z: float, n: int = 11):
    """A square grid (n x n vertices) at depth z: (vertices, faces)."""
    import numpy as np

    g = np.linspace(lo, hi, n)
    x, y = np.meshgrid(g, g)
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    f = [[i * n + j, i * n + j + 1, i * n + j + n + 1] for i in range(n - 1) for j in range(n - 1)]
    f += [[i * n + j, i * n + j + n + 1, i * n + j + n] for i in range(n - 1) for j in range(n - 1)]
    return v, np.asarray(f)


def test_the_mouth_cavity_is_what_the_lips_hide_and_draws_dark(tmp_path):
    """A wall behind a closed 'face' plane is the cavity (dark), the face plane is not; a wall
    nobody hides (the face cut away) is not either. Drawn with it, the cavity's pixels darken."""
    import numpy as np

    from faceforge.viz.smooth import draw_smooth, mouth_cavity

    front, ff = _plane(-2.0, 2.0, 0.0, 41)   # fine enough that its triangles lie in the box
    back, bf = _plane(-0.5, 0.5, -0.5)
    v = np.concatenate([front, back])
    f = np.concatenate([ff, bf + len(front)])
    args = ((0, 0.02, 0), (0, -0.02, 0), ((1.0, 0, 0), (-1.0, 0, 0)), ((0, 0.3, 0), (0, -0.3, 0)), 0.01)
    dim = mouth_cavity(v, f, *args, soften=0)                               # the hidden set itself
    behind = np.arange(len(front), len(v))
    in_box = behind[np.abs(v[behind, 1]) < 0.15]
    assert np.all(dim[in_box] == 1.0) and np.all(dim[: len(front)] == 0.0)
    assert np.all(dim[behind[np.abs(v[behind, 1]) > 0.35]] == 0.0)        # outside the lips' band
    alone = mouth_cavity(back, bf, *args)                                   # nothing in front of it
    assert not alone.any()
    # a deep wall (a mouth bag's, 50 mm back) stays whole: every hidden vertex and the deep ones
    # sharing a triangle with them (a coarse bag's triangles cross the box's edge)
    deep = mouth_cavity(v, f, *args)
    assert np.all(deep[in_box] == 1.0) and np.all(deep[: len(front)] == 0.0)
    assert np.all(deep[behind[np.isclose(np.abs(v[behind, 1]), 0.2)]] == 1.0)   # the box's next row
    # a shallow one (the rolled-in lips, 2 mm back): softened, its edge a ramp, not a step
    shallow = np.concatenate([front, back + (0, 0, 0.48)])
    raw, soft = mouth_cavity(shallow, f, *args, soften=0), mouth_cavity(shallow, f, *args)
    edges = bf + len(front)
    step = lambda d: np.abs(d[edges] - d[np.roll(edges, 1, axis=1)]).max()
    assert step(raw) == 1.0 and step(soft) <= 0.5
    assert soft[behind[np.abs(v[behind, 1]) < 0.05]].min() > 0.8 and np.all(soft[: len(front)] == 0.0)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def mean_light(d):
        fig, ax = plt.subplots()
        draw_smooth(ax, back, bf, dim=d)
        ax.set_xlim(-0.6, 0.6)
        ax.set_ylim(-0.6, 0.6)
        ax.axis("off")
        fig.canvas.draw()
        img = np.asarray(fig.canvas.buffer_rgba(), dtype=float)[..., :3]
        plt.close(fig)
        return img.mean()

    assert mean_light(np.ones(len(back))) < 0.8 * mean_light(None)


def test_a_hole_one_sees_through_is_drawn_dark_not_white():
    """A plane with a square hole (a mask's mouth): the hole's pixels are the cavity's dark,
    the page round the plane stays white, and the plane itself is lit skin; the heat map
    draws the hole dark too (the image of a surface covers its outer rim's inside, so the
    rim's fill never shows)."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from faceforge.viz.smooth import draw_heat, draw_smooth

    v, f = _plane(-1.0, 1.0, 0.0, 11)
    centre = np.abs(v[f][:, :, :2]).max(axis=1).max(axis=1) <= 0.4 + 1e-9   # the middle 4 x 4 cells
    f = f[~centre]

    def pixels(draw):
        fig, ax = plt.subplots(figsize=(3, 3), dpi=100)
        draw(ax)
        ax.set_xlim(-1.5, 1.5)
        ax.set_ylim(-1.5, 1.5)
        ax.axis("off")
        fig.subplots_adjust(0, 0, 1, 1)
        fig.canvas.draw()
        img = np.asarray(fig.canvas.buffer_rgba(), dtype=float)[..., :3] / 255.0
        plt.close(fig)
        return img[150, 150], img[5, 5], img[150, 60]      # hole, page, plane (x = -0.7)

    hole, page, skin = pixels(lambda ax: draw_smooth(ax, v, f))
    assert hole.max() < 0.25 and page.min() > 0.99 and skin.mean() > 0.6
    hole, page, _ = pixels(lambda ax: draw_heat(ax, v, v, f, 1.0))
    assert hole.max() < 0.25 and page.min() > 0.99
