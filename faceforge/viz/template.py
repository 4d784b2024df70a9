"""Pictures of the template: the skull and the muscle map, front and side (Figs. 6, 7, 8a).

:func:`render_template` draws each muscle as a coloured, labelled sheet lying on the
skull, at rest or with a jaw pose and contractions. The sheet is a drawing proxy built
from the muscle's contour (a Coons patch between its four action lines, h x w samples,
projected onto the skull and lifted by its layer and thickness); it follows the jaw
because each sample is a surface point (triangle + barycentric coordinates) of the
skull. Contractions are drawn the way the action lines move them: a linear muscle's
samples slide towards the origin with step' = step (1 - c) (Eq. 4); the sphincter's
loops close towards their centre (§5.2.2, cosine fall-off across the loop's width).
The physical muscle model (faceforge.anatomy.muscles.muscle) is not run here.
"""

from __future__ import annotations

import numpy as np

from faceforge.viz.render import Layer, draw_layers

#: one colour per muscle (left and right share it), RGB in [0, 1]
PALETTE = {
    "masseter": (0.62, 0.25, 0.25), "platysma": (0.85, 0.62, 0.55), "corrugator_supercilii": (0.55, 0.2, 0.6),
    "mentalis": (0.9, 0.45, 0.2), "fatty_tissue": (0.98, 0.85, 0.4), "frontalis_inner": (0.2, 0.45, 0.8),
    "frontalis_outer": (0.35, 0.65, 0.95), "depressor_labii_inferioris": (0.45, 0.7, 0.3),
    "levator_labii_inner": (0.85, 0.3, 0.55), "levator_labii_outer": (0.95, 0.5, 0.7),
    "zygomaticus_major": (0.85, 0.15, 0.15), "risorius": (0.2, 0.7, 0.7), "depressor_anguli": (0.3, 0.5, 0.2),
    "orbicularis_oris": (0.75, 0.1, 0.35), "depressor_supercilii": (0.25, 0.8, 0.45),
    "orbicularis_oculi": (0.3, 0.6, 0.65),
}
BONE_COLOUR = (0.91, 0.89, 0.83)
MANDIBLE_COLOUR = (0.86, 0.88, 0.9)


def colour_of(name: str) -> tuple:
    """The palette colour of a muscle (side suffix ignored); grey for unknown names."""
    base = name[:-2] if name.endswith(("_L", "_R")) else name
    if base in PALETTE:
        return PALETTE[base]
    rng = np.random.default_rng(abs(hash(base)) % (2**32))
    return tuple(0.3 + 0.6 * rng.random(3))


def resample(polyline: np.ndarray, n: int, closed: bool = False) -> np.ndarray:
    """``n`` points at equal arc-length steps along a polyline (k, 3) (Eq. 3 spacing)."""
    p = np.asarray(polyline, dtype=np.float64)
    if closed:
        p = np.vstack([p, p[:1]])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    t = np.linspace(0.0, s[-1], n + 1 if closed else n)[: n]
    return np.stack([np.interp(t, s, p[:, k]) for k in range(3)], axis=1)


def muscle_sheet(spec, contraction: float = 0.0) -> np.ndarray:
    """(h, w, 3) sample grid of a muscle's contour in template space (not projected).

    Linear: rows run origin -> insertion along the fibres, a Coons patch of A3, A1, A0, A2;
    with contraction c the rows cover the fraction (1 - c) of the fibres from the origin.
    Sphincter: rows are h points around the loops, columns w steps inner -> outer; with c
    the loops are pulled towards the centre (o - s) c cos(pi/2 * r), r = 0 inner .. 1 outer.
    """
    h, w = spec.h, spec.w
    c = float(np.clip(contraction if spec.active else 0.0, 0.0, 1.0))
    lines = spec.action_lines()
    if spec.type == "linear":
        a0 = resample(lines["A0"], h)
        a2 = resample(lines["A2"], h)
        org = resample(lines["A3"], w)
        ins = resample(lines["A1"], w)
        u = np.linspace(0.0, 1.0 - c, h)[:, None, None]
        v = np.linspace(0.0, 1.0, w)[None, :, None]
        a0u = np.stack([np.interp(u[:, 0, 0], np.linspace(0, 1, h), a0[:, k]) for k in range(3)], 1)[:, None]
        a2u = np.stack([np.interp(u[:, 0, 0], np.linspace(0, 1, h), a2[:, k]) for k in range(3)], 1)[:, None]
        ruled_fibres = (1 - v) * a0u + v * a2u
        ruled_sites = (1 - u) * org[None] + u * ins[None]
        corners = ((1 - u) * (1 - v) * org[0] + (1 - u) * v * org[-1] + u * (1 - v) * ins[0] + u * v * ins[-1])
        return ruled_fibres + ruled_sites - corners
    inner = resample(lines["A1"], h, closed=True)
    outer = resample(lines["A3"], h, closed=True)
    r = np.linspace(0.0, 1.0, w)[None, :, None]
    grid = (1 - r) * inner[:, None] + r * outer[:, None]
    centre = np.vstack([inner, outer]).mean(0)
    return grid + (centre - grid) * c * np.cos(0.5 * np.pi * r) * 0.6


def refine(grid: np.ndarray, closed: bool, factor: int = 3) -> np.ndarray:
    """Bilinear refinement of an (h, w, 3) grid by ``factor`` (rows wrap when ``closed``)."""
    h, w, _ = grid.shape
    g = np.concatenate([grid, grid[:1]]) if closed else grid
    rows = (h if closed else h - 1) * factor + (0 if closed else 1)
    u = np.arange(rows) / factor
    v = np.linspace(0.0, w - 1, (w - 1) * factor + 1)
    i0 = np.minimum(np.floor(u).astype(int), g.shape[0] - 2)
    j0 = np.minimum(np.floor(v).astype(int), w - 2)
    fu = (u - i0)[:, None, None]
    fv = (v - j0)[None, :, None]
    a = g[i0][:, j0]
    b = g[i0][:, j0 + 1]
    c = g[i0 + 1][:, j0]
    d = g[i0 + 1][:, j0 + 1]
    return (1 - fu) * ((1 - fv) * a + fv * b) + fu * ((1 - fv) * c + fv * d)


def grid_faces(h: int, w: int, closed: bool = False) -> np.ndarray:
    """Triangles (m, 3) of an h x w grid (row-major ids); rows wrap when ``closed``."""
    rows = h if closed else h - 1
    out = []
    for i in range(rows):
        i1 = (i + 1) % h
        for j in range(w - 1):
            a, b, c, d = i * w + j, i * w + j + 1, i1 * w + j, i1 * w + j + 1
            out += [(a, c, b), (b, c, d)]
    return np.asarray(out, dtype=np.int64)


class _PosedSkull:
    """Skull at a jaw pose + surface-point lookups of template-space points."""

    def __init__(self, skull, jaw):
        from faceforge.anatomy.skull import apply_transform, jaw_transform
        from faceforge.geometry.surface_points import SurfaceProjector

        self.rest_v, self.f, self.bone = skull.combined()
        self.rest = SurfaceProjector(self.rest_v, self.f)
        self.t = jaw_transform(skull, *jaw)
        self.v, _, _ = skull.combined(*jaw)
        self.apply = apply_transform

    def place(self, points: np.ndarray, lift: float, with_normals: bool = False):
        """Project rest-space points onto the rest skull, carry them to the pose, lift along normals."""
        from faceforge.geometry.triangles import barycentric, face_normals

        p = points.reshape(-1, 3)
        closest, _, tri = self.rest.closest(p)
        bary = barycentric(closest, self.rest_v, self.f, tri)
        posed = np.einsum("kj,kjd->kd", bary, self.v[self.f[tri]])
        normals = face_normals(self.v, self.f[tri])
        out = (posed + lift * normals).reshape(points.shape)
        return (out, normals.reshape(points.shape)) if with_normals else out


def _coons(left, right, bottom, top, closed: bool) -> np.ndarray:
    """(h, w, 3) patch from its boundary columns (h, 3) and rows (w, 3); ruled when ``closed``."""
    h, w = len(left), len(bottom)
    v = np.linspace(0.0, 1.0, w)[None, :, None]
    ruled = (1 - v) * left[:, None] + v * right[:, None]
    if closed:
        return ruled
    u = np.linspace(0.0, 1.0, h)[:, None, None]
    corners = ((1 - u) * (1 - v) * bottom[0] + (1 - u) * v * bottom[-1] + u * (1 - v) * top[0] + u * v * top[-1])
    return ruled + (1 - u) * bottom[None] + u * top[None] - corners


def place_sheet(ps: "_PosedSkull", grid: np.ndarray, closed: bool, lift: float) -> np.ndarray:
    """Drawable (h, w, 3) sheet: contour on the (posed) skull, interior bridging over gaps.

    Like the muscle model (§5.1.2), only the contour is attached to the surface: the
    contour samples become surface points; the interior is the Coons patch of the placed
    contour, pushed out onto the skull where the skull bulges above it (forehead) and left
    bridging where the skull falls away (the cheek between zygoma, teeth and ramus).
    """
    def border(g):
        return g[:, 0], g[:, -1], g[0], g[-1]

    placed = [ps.place(b, lift) for b in border(grid)]
    bridge = _coons(*placed, closed)
    rest_bridge = _coons(*border(grid), closed)
    surf, normals = ps.place(rest_bridge, lift, with_normals=True)
    above = np.einsum("hwk,hwk->hw", surf - bridge, normals) > 0.0
    out = np.where(above[..., None], surf, bridge)
    out[:, 0], out[:, -1] = placed[0], placed[1]
    if not closed:
        out[0], out[-1] = placed[2], placed[3]
    return out


def muscle_layers(skull, muscles, jaw=(0.0, 0.0, 0.0), contractions=None, meshes=None) -> list[Layer]:
    """Drawable layers: cranium, mandible (posed) and one sheet per muscle.

    ``meshes`` ({muscle name: (vertices (n, 3), faces (m, 3))}, e.g. simulated muscle
    meshes of the layered model) replaces the drawing proxy of the muscles it names.
    """
    ps = _PosedSkull(skull, jaw)
    nc = len(skull.cranium[0])
    out = [Layer(ps.v[:nc], skull.cranium[1], BONE_COLOUR),
           Layer(ps.v[nc:], skull.mandible[1], MANDIBLE_COLOUR)]
    diag = skull.diagonal
    contractions = contractions or {}
    meshes = meshes or {}
    for spec in sorted(muscles, key=lambda s: s.layer):
        if spec.name in meshes:
            mv, mf = meshes[spec.name]
            out.append(Layer(np.asarray(mv, dtype=float), np.asarray(mf), colour_of(spec.name),
                             label=_short(spec.name)))
            continue
        closed = spec.type == "sphincter"
        grid = refine(muscle_sheet(spec, contractions.get(spec.name, 0.0)), closed)
        # deeper layers first: each layer lifted above the previous ones so the picture shows
        # the stacking (the lift is for drawing only)
        lift = diag * (0.003 + 0.01 * spec.layer) + 0.3 * spec.absolute_thickness(diag)
        pts = place_sheet(ps, grid, closed, lift)
        faces = grid_faces(grid.shape[0], grid.shape[1], closed=closed)
        out.append(Layer(pts.reshape(-1, 3), faces, colour_of(spec.name), label=_short(spec.name)))
    return out


def _short(name: str) -> str:
    words = {"supercilii": "sup", "inferioris": "inf", "labii": "lab", "levator": "lev", "depressor": "dep",
             "zygomaticus": "zyg", "orbicularis": "orb", "frontalis": "front", "corrugator": "corr",
             "fatty": "fat", "tissue": "", "major": "maj", "anguli": "ang", "inner": "in", "outer": "out"}
    parts = [words.get(p, p) for p in name.split("_")]
    return " ".join(p for p in parts if p)


def render_template(skull, muscles, out_png, jaw=(0.0, 0.0, 0.0), contractions=None,
                    views=("front", "side"), title: str | None = None, landmarks: bool = False,
                    size: float = 6.0, dpi: int = 150, meshes=None) -> None:
    """Draw the skull and the muscle map (front and side) into ``out_png``; headless (Agg).

    Parameters
    ----------
    skull : anatomy.skull.Skull
    muscles : list of anatomy.muscles.muscle_map.MuscleSpec
    out_png : path of the PNG to write
    jaw : (pitch rad, yaw rad, protrusion template units)
    contractions : {muscle name: c in [0, 1]} or None (passive muscles ignore theirs)
    landmarks : also mark the skull's FDP landmarks (posed with the jaw)
    meshes : {muscle name: (vertices, faces)} drawn instead of the contour proxy (e.g. the
        muscle meshes of a simulated frame, Fig. 7)
    """
    import matplotlib.pyplot as plt

    from faceforge.anatomy.skull import posed_landmarks

    layers = muscle_layers(skull, muscles, jaw, contractions, meshes)
    pts = None
    if landmarks:
        pts = np.array(list(posed_landmarks(skull, *jaw).values()))
    fig, axes = plt.subplots(1, len(views), figsize=(size * len(views), size * 1.15), dpi=dpi)
    axes = np.atleast_1d(axes)
    for ax, view in zip(axes, views):
        draw_layers(ax, layers, view, points=pts)
        ax.set_title(view, fontsize=9)
    if title is None:
        pose = f"jaw pitch {jaw[0]:.2f} rad, yaw {jaw[1]:.2f} rad, protrusion {jaw[2]:.2f}"
        active = ", ".join(f"{k} {v:.2f}" for k, v in (contractions or {}).items() if v)
        title = f"{len(muscles)} muscles; {pose}" + (f"; contracted: {active}" if active else "")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out_png)
    plt.close(fig)
