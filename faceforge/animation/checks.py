"""Physical checks over finished frames (paper §9's results, measured): non-finite positions,
triangles turned over, new creases (folded edges), skin inside the skull.

:func:`check_animation` gives the animate stage's ``report.json`` ``checks``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np


def inverted_faces(rest: np.ndarray, frames: np.ndarray, faces: np.ndarray,
                   tol: float = 0.0) -> np.ndarray:
    """Which triangles are turned over in each frame, relative to the rest pose.

    A triangle is inverted when its normal turns more than 90 degrees from its rest
    normal (``n_rest . n_frame <= tol``, both unnormalized: area-weighted), however small
    the triangle: the lip corners of a dense head are made of triangles of 0.1-20 % of the
    median area and a fold there is a visible crease. Only rest triangles without a normal
    are skipped: numerically degenerate ones, area <= 1e-12 of the squared bounding-box
    diagonal of ``rest``. rest (n, 3), frames (F, n, 3), faces (m, 3) -> (F, m) bool.
    """
    f = np.asarray(faces, dtype=np.int64)
    rest = np.asarray(rest, dtype=float)
    r = rest[f]
    n0 = np.cross(r[:, 1] - r[:, 0], r[:, 2] - r[:, 0])
    diag2 = float(np.sum(np.ptp(rest, axis=0) ** 2)) if len(rest) else 0.0
    ok = 0.5 * np.linalg.norm(n0, axis=1) > 1e-12 * diag2
    out = np.zeros((len(frames), len(f)), dtype=bool)
    for i, p in enumerate(np.asarray(frames)):
        t = p[f]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        out[i] = (np.einsum("ij,ij->i", n0, n) <= tol) & ok
    return out


def inverted_triangles(rest: np.ndarray, frames: np.ndarray, faces: np.ndarray,
                       tol: float = 0.0) -> np.ndarray:
    """Per frame, how many triangles are turned over (:func:`inverted_faces`) -> (F,) int."""
    return inverted_faces(rest, frames, faces, tol).sum(axis=1).astype(np.int64)


#: an edge is folded when its two triangles turn more than FOLD_DEG from each other where at
#: rest they turned less than FLAT_DEG (:func:`folded_edges`)
FOLD_DEG, FLAT_DEG = 90.0, 60.0


def folded_edges(rest: np.ndarray, frames: np.ndarray, faces: np.ndarray,
                 fold_deg: float = FOLD_DEG, flat_deg: float = FLAT_DEG) -> np.ndarray:
    """Which interior skin edges are folded in each frame: creases the skin did not have.

    An edge (of :func:`faceforge.skin.layer.skin_topology`'s bending quads) is folded when the
    normals of its two triangles turn more than ``fold_deg`` from each other while at rest they
    turned less than ``flat_deg`` -- the upper lip crumpled under the nose, say, with no
    triangle turned over (:func:`inverted_faces` sees none). Real skin wrinkles too (the
    forehead raising the brows), so this is a measure, not a failure. rest (n, 3), frames
    (F, n, 3), faces (m, 3) -> (F, q) bool.
    """
    from faceforge.pbd.constraints.bending import dihedral_angle

    quads = _bending_quads(faces)
    flat = np.abs(dihedral_angle(rest, quads)) < np.radians(flat_deg)
    limit = np.radians(fold_deg)
    out = np.zeros((len(frames), len(quads)), dtype=bool)
    for i, p in enumerate(np.asarray(frames)):
        out[i] = flat & (np.abs(dihedral_angle(p, quads)) > limit)
    return out


_QUADS: dict = {}


def _bending_quads(faces) -> np.ndarray:
    """:func:`faceforge.skin.layer.skin_topology`'s ``bending_quads`` of ``faces (m, 3)``, kept for
    the last few face arrays by content (a bake checks ~60 shapes of one mesh: each rebuilt the
    topology, ~20 ms). Read-only."""
    import hashlib

    from faceforge.skin.layer import skin_topology

    f = np.ascontiguousarray(faces, dtype=np.int64)
    key = (f.shape, hashlib.blake2b(f.tobytes(), digest_size=16).hexdigest())
    quads = _QUADS.get(key)
    if quads is None:
        quads = np.asarray(skin_topology(f).bending_quads)
        quads.setflags(write=False)
        while len(_QUADS) >= 4:
            _QUADS.pop(next(iter(_QUADS)))
        _QUADS[key] = quads
    return quads


def points_inside(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k,) bool: which ``points`` (k, 3) lie inside the closed mesh (vertices, faces).

    Ray parity along +X and -X (both must agree), with the top-left rule deciding rays through
    an edge or a vertex: a one-shot :class:`faceforge.geometry.parity.ParityGrid` (build it
    once to query a mesh repeatedly, as bone collision does).
    """
    return _grid(vertices, faces).contains(points)


#: the last few meshes' parity grids, keyed by a digest of their arrays: a bake checks 40 shapes
#: against the same bones (rest jaw), each grid costs ~0.05 s to build
_GRIDS: dict = {}


def _grid(vertices, faces):
    """:class:`faceforge.geometry.parity.ParityGrid` of (vertices (n, 3), faces (m, 3)), reused
    while the same arrays (byte for byte) come back."""
    import hashlib

    from faceforge.geometry.parity import ParityGrid

    v, f = np.ascontiguousarray(vertices, dtype=float), np.ascontiguousarray(faces, dtype=np.int64)
    key = (v.shape, f.shape, hashlib.blake2b(v.tobytes() + f.tobytes(), digest_size=16).digest())
    if key not in _GRIDS:
        if len(_GRIDS) >= 4:
            _GRIDS.pop(next(iter(_GRIDS)))
        _GRIDS[key] = ParityGrid(v, f)
    return _GRIDS[key]


def inside_bones(points: np.ndarray, bodies) -> np.ndarray:
    """(k,) bool: which ``points`` (k, 3) lie inside any of the closed meshes ``bodies``
    (a list of (vertices, faces))."""
    out = np.zeros(len(points), dtype=bool)
    for v, f in bodies:
        out |= points_inside(points, v, f)
    return out


def _depth_below(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k,) distance from each point (inside the mesh) to the mesh surface."""
    from faceforge.geometry.surface_points import closest_points

    return closest_points(np.asarray(points, float), vertices, faces)[1]


#: a skin vertex moved farther than this fraction of the skin's bounding-box diagonal fails the
#: checks: no muscle or jaw pose moves skin that far (the samples' presets 4-8 %, the ARKit shapes
#: at most 12 %, MediaPipe's jawOpen on a face mask), a vertex thrown by the solver does (a dense
#: scan's proxy threw a mouth-corner vertex 30-36 % in disgust, and the checks said ok)
THROWN = 0.25


def displacement_limit(rest: np.ndarray) -> float:
    """The farthest a skin vertex of ``rest (n, 3)`` may move and pass the checks (skin units):
    :data:`THROWN` of its bounding-box diagonal."""
    return THROWN * float(np.linalg.norm(np.ptp(np.asarray(rest, dtype=float), axis=0))) if len(rest) else np.inf


def fold_limit(n_edges: int) -> int:
    """Most skin edges one frame may fold and still pass the checks: 0.5 % of the ``n_edges``
    interior edges checked, at least 32 (the sample heads fold at most 12 on their tracks)."""
    return max(32, int(0.005 * n_edges))


@dataclass
class FrameReport:
    """Named physical checks over an animation (all counts are totals over frames)."""

    frames: int
    non_finite: int
    inverted_triangles: int
    skin_inside_skull: int
    max_displacement: float
    worst_frame: int = -1
    notes: list = field(default_factory=list)
    #: distinct triangles turned over in at least one frame, and the most in one frame
    inverted_faces: int = 0
    inverted_max_per_frame: int = 0
    #: distinct skin edges folded in at least one frame, and the most in one frame
    #: (:func:`folded_edges`); :attr:`ok` fails when one frame folds more than ``fold_limit``
    folded_edges: int = 0
    folded_max_per_frame: int = 0
    fold_limit: int = 1 << 62
    #: :func:`displacement_limit`: :attr:`ok` fails when a vertex moves farther (thrown)
    displacement_limit: float = float("inf")
    #: where each check failed: ``{"non_finite": first frame, "inverted": first frame,
    #: "folded": the frame folding the most edges, "inside_skull": {frame: vertices}}`` (only
    #: the checks that found something; the skull is tested on the sampled frames only)
    where: dict = field(default_factory=dict)
    #: a proxy-simulated head's (fit.simulation_vertices) user mesh carried on the frames:
    #: ``{"inverted_faces": distinct user triangles turned over, "inverted_max_per_frame",
    #: "inverted_triangles": the sum over frames, "inverted": first frame}``; None: no proxy
    carried: dict | None = None

    @property
    def ok(self) -> bool:
        """No NaN, no triangle turned over, no skin inside the bone, no frame folding more
        than ``fold_limit`` edges (a few new creases are a soft face; hundreds are a crumpled one:
        a FAP of 1e9 folded 408 edges and still said ok) and no vertex thrown farther than
        ``displacement_limit``."""
        return (self.non_finite == 0 and self.inverted_triangles == 0 and self.skin_inside_skull == 0
                and self.folded_max_per_frame <= self.fold_limit
                and self.max_displacement <= self.displacement_limit
                and (self.carried is None or self.carried["inverted_triangles"] == 0))

    def as_dict(self) -> dict:
        return {"frames": self.frames, "non_finite": self.non_finite,
                "inverted_triangles": self.inverted_triangles,
                "inverted_faces": self.inverted_faces,
                "inverted_max_per_frame": self.inverted_max_per_frame,
                "folded_edges": self.folded_edges, "folded_max_per_frame": self.folded_max_per_frame,
                "fold_limit": self.fold_limit, "displacement_limit": self.displacement_limit,
                "skin_inside_skull": self.skin_inside_skull,
                "max_displacement": self.max_displacement, "worst_frame": self.worst_frame,
                "ok": self.ok, "notes": list(self.notes), "where": dict(self.where),
                **({} if self.carried is None else {"carried": dict(self.carried)})}


class CarriedInversions:
    """Turned-over triangles of a dense mesh carried on a proxy's frames (fit.simulation_vertices),
    counted a chunk at a time: ``rest (n, 3)`` and ``faces (t, 3)`` of the carried mesh."""

    def __init__(self, rest: np.ndarray, faces: np.ndarray):
        self.rest, self.faces = np.asarray(rest, dtype=float), np.asarray(faces, dtype=np.int64)
        self.any = np.zeros(len(self.faces), bool)
        self.total, self.max, self.first, self.seen = 0, 0, None, 0

    def add(self, frames: np.ndarray) -> None:
        """The next carried ``frames (k, n, 3)``."""
        flips = inverted_faces(self.rest, np.nan_to_num(np.asarray(frames, dtype=float)), self.faces)
        per = flips.sum(axis=1)
        self.any |= flips.any(axis=0)
        self.total += int(per.sum())
        self.max = max(self.max, int(per.max()) if len(per) else 0)
        if self.first is None and per.any():
            self.first = self.seen + int(np.argmax(per > 0))
        self.seen += len(flips)

    def as_dict(self) -> dict:
        """The :attr:`FrameReport.carried` mapping."""
        return {"inverted_faces": int(self.any.sum()), "inverted_max_per_frame": self.max,
                "inverted_triangles": self.total, "inverted": self.first}


def check_animation(rest: np.ndarray, frames: np.ndarray, faces: np.ndarray,
                    skull: Sequence | None = None, sample: int = 8,
                    tolerance: float | None = None, inside_at_rest: np.ndarray | None = None) -> FrameReport:
    """NaN, inverted skin triangles, skin inside the skull over an animation.

    ``inverted_triangles`` is the sum over frames of the triangles turned over
    (:func:`inverted_faces`); ``inverted_faces`` how many distinct triangles that is.
    ``folded_edges`` / ``folded_max_per_frame``: the skin's new creases (:func:`folded_edges`).

    rest (n, 3), frames (F, n, 3), faces (m, 3) of the skin; ``skull`` optionally a list of
    closed meshes (vertices, faces) **per checked frame** is expensive, so it is a callable
    ``frame_index -> list of (vertices, faces)``; ``sample`` frames (evenly spaced, always the
    one with the largest displacement) are checked against it. Vertices already inside at
    rest (e.g. teeth-adjacent folds) are not counted, nor vertices less than ``tolerance``
    (skin units; default 1e-3 of the skin's bounding-box diagonal) below the bone surface;
    ``inside_at_rest`` (n,) bool: those vertices when the caller has them (:func:`inside_bones`
    of ``rest`` in ``skull(-1)``; a bake checks 40 shapes against one rest).
    """
    if tolerance is None:
        tolerance = 1e-3 * float(np.linalg.norm(np.ptp(np.asarray(rest, dtype=float), axis=0)))
    frames = np.asarray(frames, dtype=float)
    finite = np.isfinite(frames).all(axis=(1, 2))
    disp = np.linalg.norm(np.nan_to_num(frames) - rest, axis=2).max(axis=1)
    worst = int(np.argmax(disp)) if len(disp) else -1
    flips = inverted_faces(rest, np.nan_to_num(frames), faces)
    inv = flips.sum(axis=1)
    folds = folded_edges(rest, np.nan_to_num(frames), faces)
    where = _where(finite, inv, folds.sum(axis=1))
    inside = {}
    if skull is not None and len(frames):
        idx = sorted(set(np.linspace(0, len(frames) - 1, min(sample, len(frames))).astype(int)) | {worst})
        inside = inside_skull(rest, frames, idx, skull, tolerance, inside_at_rest)
        if inside:
            where["inside_skull"] = inside
    inside_total = sum(inside.values())
    return FrameReport(frames=len(frames), non_finite=int(np.count_nonzero(~finite)),
                       inverted_triangles=int(inv.sum()), skin_inside_skull=inside_total,
                       max_displacement=float(disp.max()) if len(disp) else 0.0, worst_frame=worst,
                       inverted_faces=int(flips.any(axis=0).sum()),
                       inverted_max_per_frame=int(inv.max()) if len(inv) else 0,
                       folded_edges=int(folds.any(axis=0).sum()),
                       folded_max_per_frame=int(folds.sum(axis=1).max()) if len(folds) else 0,
                       fold_limit=fold_limit(folds.shape[1]), where=_thrown(where, disp, rest),
                       displacement_limit=displacement_limit(rest))


def inside_skull(rest: np.ndarray, frames, idx, skull, tolerance: float,
                 inside_at_rest: np.ndarray | None = None) -> dict:
    """``{str(frame): count}`` of the skin vertices newly inside the bones, for each frame of
    ``idx`` with any: ``frames[i] (n, 3)`` (an array or a mapping), ``skull`` the callable
    ``frame_index -> [(vertices, faces)]`` of :func:`check_animation` (``-1``: at rest), vertices
    inside at rest (``inside_at_rest (n,)`` bool, or computed once from ``skull(-1)``) and those
    less than ``tolerance`` (skin units) below the bone surface not counted."""
    base, out = inside_at_rest, {}
    for i in idx:
        bodies = skull(i)
        if base is None:
            base = inside_bones(rest, skull(-1))
        now = np.zeros(len(rest), dtype=bool)
        for v, f in bodies:
            inside = points_inside(frames[i], v, f)
            if inside.any() and tolerance > 0:
                inside[inside] = _depth_below(frames[i][inside], v, f) > tolerance
            now |= inside
        count = int(np.count_nonzero(now & ~base))
        if count:
            out[str(int(i))] = count
    return out


def _thrown(where: dict, disp: np.ndarray, rest: np.ndarray) -> dict:
    """``where`` with ``"thrown": first frame`` when a frame's largest displacement (``disp (F,)``)
    passes :func:`displacement_limit` of ``rest``."""
    over = np.flatnonzero(np.asarray(disp) > displacement_limit(rest))
    return {**where, "thrown": int(over[0])} if len(over) else where


def _where(finite: np.ndarray, inverted: np.ndarray, folded: np.ndarray, start: int = 0) -> dict:
    """The frames where the per-frame checks found something: ``finite (F,) bool``,
    ``inverted (F,)`` and ``folded (F,)`` counts -> ``{"non_finite": first frame, "inverted": first
    frame, "folded": [frame, count] of the most folded}`` (frame numbers offset by ``start``)."""
    out: dict = {}
    if len(finite) and not finite.all():
        out["non_finite"] = start + int(np.argmin(finite))
    if len(inverted) and inverted.any():
        out["inverted"] = start + int(np.argmax(inverted > 0))
    if len(folded) and folded.any():
        out["folded"] = [start + int(np.argmax(folded)), int(folded.max())]
    return out
