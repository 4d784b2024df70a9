"""The per-frame simulation loop (paper §9): controls in, skin positions out.

One frame at the motion's frame rate does, in this order (§6: the deeper layer
drives the shallower ones and never the reverse):

1. **skull**: the mandible's rigid transform from the jaw DOFs (pitch, yaw, protrusion);
2. **muscles**, layer by layer, from their contractions and the bones under them;
3. **skin**: the anchor particles follow their surface points on the deformed muscles
   and bones, then the skin's PBD constraints are projected (``solver.substeps`` x
   ``solver.iterations``);
4. the **influence map** weights the skin displacement: ``rest + w (sim - rest)``, then the
   rig's optional ``finish`` pass corrects the weighted frame in place.

The three layer steps are callables of a :class:`Rig` so the loop is independent of
how the layers are built (and testable with stand-ins); :func:`play` times each of
them per frame for the benchmark.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS


@dataclass
class Rig:
    """The layered head as three steps.

    Attributes
    ----------
    skull : callable jaw (3,) float -> bones, an opaque value (e.g. cranium and mandible
        vertices (n_b, 3) float) handed to the next two steps
    muscles : callable (contractions (m,) float in [0, 1], bones, dt s) -> muscles, opaque
        (e.g. a list of muscle vertex arrays)
    skin : callable (bones, muscles, dt s) -> (n, 3) float skin positions (working mesh)
    rest : (n, 3) float, the skin at rest (working mesh)
    influence : (n,) float in [0, 1] or None (all ones)
    reset : callable () -> None, back to the rest state (optional)
    finish : callable (n, 3) float64 -> None, applied in place to each weighted frame (optional;
        e.g. :meth:`faceforge.anatomy.orientation_guard.OrientationGuard.apply`: the influence map
        blends rest and simulation with weights that vary from vertex to vertex, which can
        turn over a triangle the simulation kept upright)
    """

    skull: Callable
    muscles: Callable
    skin: Callable
    rest: np.ndarray
    influence: np.ndarray | None = None
    reset: Callable | None = None
    finish: Callable | None = None


@dataclass
class Timings:
    """Wall-clock seconds spent per layer, summed over ``frames`` frames."""

    skull: float = 0.0
    muscles: float = 0.0
    skin: float = 0.0
    frames: int = 0

    def per_frame_ms(self) -> dict:
        n = max(self.frames, 1)
        out = {k: 1e3 * getattr(self, k) / n for k in ("skull", "muscles", "skin")}
        out["total"] = sum(out.values())
        return out


def play(rig: Rig, contractions: np.ndarray, jaw: np.ndarray, fps: float, progress=None,
         timings: Timings | None = None, settle: int = 0, sink=None, chunk: int = 64) -> np.ndarray | None:
    """Simulate every frame and return the weighted skin.

    Parameters
    ----------
    rig : Rig
    contractions : (F, m) float in [0, 1]
    jaw : (F, 3) float, (pitch rad, yaw rad, protrusion skin units)
    fps : float > 0; each frame advances dt = 1 / fps
    progress : optional callable wrapping an iterable (``ctx.progress``); gets ``total=`` and
        ``desc=`` keywords
    timings : optional Timings, accumulated in place
    settle : extra frames simulated at each frame's controls before it is recorded (0 for
        playback; static poses such as calibration use more)
    sink : optional ``sink(start, frames (k, n, 3) float64)``: the frames are handed over
        ``chunk`` at a time (``start``: the first one's index; the array is reused, copy what
        you keep) and not returned, so a take's memory does not grow with its length

    Returns
    -------
    (F, n, 3) float64 skin positions of the working mesh, influence-weighted (None with ``sink``).

    Raises
    ------
    FloatingPointError if a frame produced a non-finite position (names the frame).
    """
    contractions = np.atleast_2d(np.asarray(contractions, dtype=float))
    jaw = np.atleast_2d(np.asarray(jaw, dtype=float))
    if len(contractions) != len(jaw) or jaw.shape[1] != 3:
        raise ValueError(f"contractions {contractions.shape} and jaw {jaw.shape} must be (F, m) and (F, 3)")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    dt = 1.0 / fps
    rest = np.asarray(rig.rest, dtype=float)
    w = np.ones(len(rest)) if rig.influence is None else np.asarray(rig.influence, dtype=float)
    if w.shape != (len(rest),):
        raise ValueError(f"influence must be ({len(rest)},), got {w.shape}")
    size = len(jaw) if sink is None else max(1, min(int(chunk), len(jaw)))
    out = np.empty((size, len(rest), 3))
    w3 = w[:, None]
    frames = range(len(jaw))
    if progress is not None:
        frames = progress(frames, total=len(jaw), desc="frames")
    t = timings if timings is not None else Timings()
    for i in frames:
        for _ in range(settle + 1):
            t0 = time.perf_counter()
            bones = rig.skull(jaw[i])
            t1 = time.perf_counter()
            muscles = rig.muscles(contractions[i], bones, dt)
            t2 = time.perf_counter()
            skin = rig.skin(bones, muscles, dt)
            t3 = time.perf_counter()
            t.skull += t1 - t0
            t.muscles += t2 - t1
            t.skin += t3 - t2
            t.frames += 1
        skin = np.asarray(skin, dtype=float)
        if not np.all(np.isfinite(skin)):
            raise FloatingPointError(f"frame {i}: the simulation produced non-finite skin positions")
        j = i % size
        frame = out[j]   # rest + w (skin - rest), in place
        np.subtract(skin, rest, out=frame)
        np.multiply(w3, frame, out=frame)
        np.add(rest, frame, out=frame)
        if rig.finish is not None:
            rig.finish(out[j])
        if sink is not None and (j == size - 1 or i == len(jaw) - 1):
            sink(i - j, out[:j + 1])
    return out if sink is None else None


def ease_in(settle: int = 30, ramp: int | None = None) -> np.ndarray:
    """Fraction of a static pose's controls at each of its frames, ``(max(settle, ramp),)``:
    linear up to 1 over ``ramp`` frames (default a third of ``settle``), then held."""
    ramp = max(1, settle // 3) if ramp is None else max(1, int(ramp))
    return np.minimum(np.arange(1, max(settle, ramp) + 1) / ramp, 1.0)


def static_poses(rig: Rig, contractions: np.ndarray, jaw: np.ndarray, fps: float,
                 settle: int = 30, ramp: int | None = None) -> np.ndarray:
    """Settled skin for each independent pose: reset, ease the controls in linearly over
    ``ramp`` frames (default a third of ``settle``), hold them to frame ``settle``.

    A pose is approached, not jumped to: the jaw thrown open to 0.34 rad in one frame made
    the orbicularis oris diverge on the MakeHuman head (a Gauss-Seidel sweep cannot absorb
    a one-frame step of a centimetre).
    contractions (k, m), jaw (k, 3) -> (k, n, 3) float. Needs ``rig.reset``.
    """
    if rig.reset is None:
        raise ValueError("static_poses needs a rig with reset()")
    t = ease_in(settle, ramp)[:, None]
    out = []
    for c, j in zip(np.atleast_2d(contractions), np.atleast_2d(jaw)):
        rig.reset()
        out.append(play(rig, t * c, t * j, fps)[-1])
    rig.reset()
    return np.stack(out) if out else np.zeros((0,) + np.shape(rig.rest))


# --------------------------------------------------------------------------- checks

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

    An edge (of :func:`faceforge.anatomy.skin.skin_topology`'s bending quads) is folded when the
    normals of its two triangles turn more than ``fold_deg`` from each other while at rest they
    turned less than ``flat_deg`` -- the upper lip crumpled under the nose, say, with no
    triangle turned over (:func:`inverted_faces` sees none). Real skin wrinkles too (the
    forehead raising the brows), so this is a measure, not a failure. rest (n, 3), frames
    (F, n, 3), faces (m, 3) -> (F, q) bool.
    """
    from faceforge.anatomy.skin import skin_topology
    from faceforge.pbd.constraints.bending import dihedral_angle

    quads = skin_topology(faces).bending_quads
    flat = np.abs(dihedral_angle(rest, quads)) < np.radians(flat_deg)
    limit = np.radians(fold_deg)
    out = np.zeros((len(frames), len(quads)), dtype=bool)
    for i, p in enumerate(np.asarray(frames)):
        out[i] = flat & (np.abs(dihedral_angle(p, quads)) > limit)
    return out


def points_inside(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k,) bool: which ``points`` (k, 3) lie inside the closed mesh (vertices, faces).

    Ray parity along +X and -X (both must agree), with the top-left rule deciding rays through
    an edge or a vertex: a one-shot :class:`faceforge.geometry.parity.ParityGrid` (build it
    once to query a mesh repeatedly, as bone collision does).
    """
    from faceforge.geometry.parity import ParityGrid

    return ParityGrid(vertices, faces).contains(points)


def _depth_below(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k,) distance from each point (inside the mesh) to the mesh surface."""
    from faceforge.geometry.surface_points import closest_points

    return closest_points(np.asarray(points, float), vertices, faces)[1]


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

    @property
    def ok(self) -> bool:
        """No NaN, no triangle turned over, no skin inside the bone, and no frame folding more
        than ``fold_limit`` edges (a few new creases are a soft face; hundreds are a crumpled one:
        a FAP of 1e9 folded 408 edges and still said ok)."""
        return (self.non_finite == 0 and self.inverted_triangles == 0 and self.skin_inside_skull == 0
                and self.folded_max_per_frame <= self.fold_limit)

    def as_dict(self) -> dict:
        return {"frames": self.frames, "non_finite": self.non_finite,
                "inverted_triangles": self.inverted_triangles,
                "inverted_faces": self.inverted_faces,
                "inverted_max_per_frame": self.inverted_max_per_frame,
                "folded_edges": self.folded_edges, "folded_max_per_frame": self.folded_max_per_frame,
                "fold_limit": self.fold_limit,
                "skin_inside_skull": self.skin_inside_skull,
                "max_displacement": self.max_displacement, "worst_frame": self.worst_frame,
                "ok": self.ok, "notes": list(self.notes)}


def check_animation(rest: np.ndarray, frames: np.ndarray, faces: np.ndarray,
                    skull: Sequence | None = None, sample: int = 8,
                    tolerance: float | None = None) -> FrameReport:
    """NaN, inverted skin triangles, skin inside the skull over an animation.

    ``inverted_triangles`` is the sum over frames of the triangles turned over
    (:func:`inverted_faces`); ``inverted_faces`` how many distinct triangles that is.
    ``folded_edges`` / ``folded_max_per_frame``: the skin's new creases (:func:`folded_edges`).

    rest (n, 3), frames (F, n, 3), faces (m, 3) of the skin; ``skull`` optionally a list of
    closed meshes (vertices, faces) **per checked frame** is expensive, so it is a callable
    ``frame_index -> list of (vertices, faces)``; ``sample`` frames (evenly spaced, always the
    one with the largest displacement) are checked against it. Vertices already inside at
    rest (e.g. teeth-adjacent folds) are not counted, nor vertices less than ``tolerance``
    (skin units; default 1e-3 of the skin's bounding-box diagonal) below the bone surface.
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
    inside_total = 0
    if skull is not None and len(frames):
        idx = sorted(set(np.linspace(0, len(frames) - 1, min(sample, len(frames))).astype(int)) | {worst})
        base = None
        for i in idx:
            bodies = skull(i)
            if base is None:
                base = np.zeros(len(rest), dtype=bool)
                for v, f in skull(-1):
                    base |= points_inside(rest, v, f)
            now = np.zeros(len(rest), dtype=bool)
            for v, f in bodies:
                inside = points_inside(frames[i], v, f)
                if inside.any() and tolerance > 0:
                    inside[inside] = _depth_below(frames[i][inside], v, f) > tolerance
                now |= inside
            inside_total += int(np.count_nonzero(now & ~base))
    return FrameReport(frames=len(frames), non_finite=int(np.count_nonzero(~finite)),
                       inverted_triangles=int(inv.sum()), skin_inside_skull=inside_total,
                       max_displacement=float(disp.max()) if len(disp) else 0.0, worst_frame=worst,
                       inverted_faces=int(flips.any(axis=0).sum()),
                       inverted_max_per_frame=int(inv.max()) if len(inv) else 0,
                       folded_edges=int(folds.any(axis=0).sum()),
                       folded_max_per_frame=int(folds.sum(axis=1).max()) if len(folds) else 0,
                       fold_limit=fold_limit(folds.shape[1]))


# --------------------------------------------------------------------------- skin vs skull

class SkullGuard:
    """Keeps skin that lies close to the bone from being pulled through it.

    Where the soft tissue is thin (nose bridge, upper lip over the maxilla, chin), a muscle
    pull or the jaw can drag a skin vertex through the skull. At rest each skin vertex
    within ``reach`` of a bone gets its nearest bone point (triangle + barycentric
    coordinates) and its rest depth ``d0`` along that triangle's normal; every frame the
    vertex is pushed back along the current normal so that its depth stays at least
    ``keep * d0`` (the tissue may thin, not vanish). Vertices inside the bone at rest (mouth
    folds around the teeth) are left alone.

    Parameters
    ----------
    rest : (n, 3) float, skin at rest
    bodies : dict name -> (vertices (v, 3), faces (f, 3)), the bones at rest
    reach : float, skin units
    keep : float in [0, 1)
    """

    def __init__(self, rest: np.ndarray, bodies: dict, reach: float, keep: float = 0.5):
        import trimesh

        from faceforge.geometry.surface_points import closest_points

        self.names = list(bodies)
        verts = [np.asarray(bodies[n][0], dtype=float) for n in self.names]
        faces = [np.asarray(bodies[n][1], dtype=np.int64) for n in self.names]
        offs = np.cumsum([0] + [len(v) for v in verts])
        foffs = np.cumsum([0] + [len(f) for f in faces])
        mesh = trimesh.Trimesh(np.vstack(verts), np.vstack([f + o for f, o in zip(faces, offs)]), process=False)
        points, dist, tri = closest_points(np.asarray(rest, dtype=float), mesh.vertices, mesh.faces)
        body = np.searchsorted(foffs, tri, side="right") - 1
        local = tri - foffs[body]
        t = mesh.triangles[tri]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        depth = np.einsum("ij,ij->i", np.asarray(rest, dtype=float) - points, n)
        inside = np.zeros(len(rest), dtype=bool)
        if len(rest):
            inside = mesh.contains(np.asarray(rest, dtype=float)) if mesh.is_watertight else depth < 0
        sel = (dist < reach) & (depth > 0.0) & ~inside
        self.vertex = np.flatnonzero(sel)
        self.body = body[sel]
        self.face = local[sel]
        self.bary = trimesh.triangles.points_to_barycentric(t[sel], points[sel])
        self.floor = keep * depth[sel]
        self.faces = faces
        # each guarded vertex's bone triangle as ids into the bodies stacked in ``names`` order
        self._ids = np.ascontiguousarray(np.asarray(mesh.faces)[tri[sel]], dtype=np.int64)
        self._slot = np.full(len(rest), -1, dtype=np.int64)   # skin vertex -> its row here, or -1
        self._slot[self.vertex] = self._all = np.arange(len(self.vertex), dtype=np.int64)
        self._mark = np.zeros(len(self.vertex), dtype=np.uint8)

    def apply(self, positions: np.ndarray, bodies_now: dict) -> int:
        """Push guarded vertices of ``positions`` (n, 3, modified in place) out to their floor.

        bodies_now : dict name -> (v, 3) current bone vertices. Returns how many moved.
        One compiled pass (:func:`_skull_guard`; its plain twin is in the tests).
        """
        if not len(self.vertex):
            return 0
        bones = np.ascontiguousarray(np.vstack([np.asarray(bodies_now[n], dtype=float) for n in self.names]))
        return self.apply_stacked(positions, bones)

    def apply_stacked(self, positions: np.ndarray, bones: np.ndarray, moved=None, only=None) -> int:
        """:meth:`apply` with the current bone vertices already stacked in :attr:`names` order,
        ``bones (sum v, 3)`` float64 C-contiguous (e.g. rows of a world mesh that starts with
        the same bodies in the same order): no per-frame copy. ``moved`` (optional, int64,
        at least ``len(vertex)`` long) receives the moved vertices in its first rows.

        ``only`` (optional, (p,) int skin vertices, repeats allowed): test just these (the
        guarded ones among them, in the guard's order); for a caller that knows every other
        guarded vertex is where a pass with the same bones left it without pushing it (a
        pushed vertex may be nudged again by round-off, so it belongs in ``only``): then the
        result is that of a full pass."""
        if not len(self.vertex):
            return 0
        if moved is None:
            moved = np.empty(len(self.vertex), dtype=np.int64)
        slots = self._all if only is None else _guarded_rows(np.asarray(only, dtype=np.int64), self._slot, self._mark)
        return int(_skull_guard(positions, self.vertex, self._ids, self.bary, self.floor, bones, moved, slots))


@numba.njit(**NUMBA_OPTIONS)
def _guarded_rows(vertices, slot, mark):
    """Ascending unique rows ``slot[v] >= 0`` of the skin vertices ``vertices (p,)`` (repeats
    allowed); ``mark`` uint8 scratch, one per row, all 0 (left so)."""
    count = 0
    for v in vertices:
        k = slot[v]
        if k >= 0 and mark[k] == 0:
            mark[k] = 1
            count += 1
    out = np.empty(count, np.int64)
    i = 0
    for k in range(mark.shape[0]):
        if mark[k]:
            out[i] = k
            i += 1
            mark[k] = 0
    return out


@numba.njit(**NUMBA_OPTIONS)
def _skull_guard(x, vertex, ids, bary, floor, bones, out, slots):
    """For each guarded vertex ``vertex[k]``, ``k`` in ``slots`` (ascending), of ``x (n, 3)``:
    its bone point ``s`` (``bary[k]`` on triangle ``ids[k]`` of ``bones``) and unit normal
    ``nrm``; where the depth ``(x - s) . nrm`` is below ``floor[k]``, move it out along ``nrm``
    to the floor. In place; returns how many moved, whose vertex ids go to the first rows of
    ``out``."""
    moved = 0
    for k in slots:
        a, b, c = ids[k, 0], ids[k, 1], ids[k, 2]
        e1x, e1y, e1z = bones[b, 0] - bones[a, 0], bones[b, 1] - bones[a, 1], bones[b, 2] - bones[a, 2]
        e2x, e2y, e2z = bones[c, 0] - bones[a, 0], bones[c, 1] - bones[a, 1], bones[c, 2] - bones[a, 2]
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        length = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-300)
        nx, ny, nz = nx / length, ny / length, nz / length
        v = vertex[k]
        sx = bary[k, 0] * bones[a, 0] + bary[k, 1] * bones[b, 0] + bary[k, 2] * bones[c, 0]
        sy = bary[k, 0] * bones[a, 1] + bary[k, 1] * bones[b, 1] + bary[k, 2] * bones[c, 1]
        sz = bary[k, 0] * bones[a, 2] + bary[k, 1] * bones[b, 2] + bary[k, 2] * bones[c, 2]
        depth = (x[v, 0] - sx) * nx + (x[v, 1] - sy) * ny + (x[v, 2] - sz) * nz
        if depth < floor[k]:
            push = floor[k] - depth
            x[v, 0] += push * nx
            x[v, 1] += push * ny
            x[v, 2] += push * nz
            out[moved] = v
            moved += 1
    return moved
