"""Muscles built as mirror images: a symmetric rig for a symmetric head (issue 25).

On a head that is its own mirror image, a right muscle built from its own (mirrored) action
lines still differs from its left twin: each line is projected onto the *outermost* surface
beneath it, and a 1-2 mm difference in the bone or the deeper muscles picks another layer, so
the twins move the skin differently (MakeHuman's zygomatici moved the two mouth corners 155 /
66 MW). :func:`mirror_muscle` builds the right twin as the exact mirror image of the left one
instead: mirrored rest particles, the left's faces with their winding reversed (a reflection
turns a surface inside out), and each action-line point on the mirror image of the left's:

* on a deeper muscle that has a mirrored twin (``X_L`` -> ``X_R``, itself built by this
  function): the same face with reversed barycentric coordinates, exactly;
* on the bone or a midline muscle (the orbicularis oris, the mentalis): the closest point of
  that body to the mirrored point (as symmetric as the body is).

:func:`symmetric_loop` makes a sphincter's loop (the orbicularis oris is its own mirror image)
symmetric: its right half is the mirror image of its left half.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from faceforge.anatomy.muscles.muscle_map import mirrored_name
from faceforge.constants import FLOAT, INT
from faceforge.geometry.surface_points import SurfacePoints, project_to_surface


def _mirror_points(points: SurfacePoints, left_parts, right_parts, mirror, exact: set) -> SurfacePoints:
    """Surface points on the concatenated ``left_parts`` [(name, (v, f))] -> their mirror images
    on the concatenated ``right_parts``; a part named in ``exact`` (a mirrored twin) maps face by
    face."""
    lstart = np.cumsum([0] + [len(f) for _, (_, f) in left_parts])
    rstart = {name: int(s) for (name, _), s in zip(right_parts, np.cumsum([0] + [len(f) for _, (_, f) in right_parts]))}
    rmesh = {name: mesh for name, mesh in right_parts}
    fid, bary = points.face_ids.copy(), points.bary.copy()
    part = np.searchsorted(lstart, points.face_ids, side="right") - 1
    for k, (lname, (lv, lf)) in enumerate(left_parts):
        sel = np.flatnonzero(part == k)
        if not len(sel):
            continue
        rname = mirrored_name(lname)
        if rname not in rstart:
            raise ValueError(f"the mirror image of {lname!r} is not among the bodies the twin lies on")
        local = points.face_ids[sel] - lstart[k]
        if lname in exact and rname != lname:
            fid[sel] = local + rstart[rname]
            bary[sel] = points.bary[sel][:, ::-1]
            continue
        p = np.einsum("ij,ijk->ik", points.bary[sel], np.asarray(lv, FLOAT)[np.asarray(lf)[local]])
        sp = project_to_surface(mirror(p), *rmesh[rname])
        fid[sel] = sp.face_ids + rstart[rname]
        bary[sel] = sp.bary
    return SurfacePoints(fid.astype(INT), bary)


def mirror_muscle(left, name: str, lies_on: tuple, left_parts, right_parts, mirror, exact: set):
    """The mirror image of the built linear Muscle ``left`` as the muscle ``name`` lying on
    ``lies_on``.

    Its action lines are the mirror images of the left's (module docstring) and its rest mesh
    is built on them as any muscle's is, so the rest state stays an exact fixed point of its
    constraints; it then differs from the mirrored left mesh only as much as the bodies beneath
    differ from their mirror images (the fitted bone). Its faces are the left's, turned, so the
    twins' surfaces correspond face by face.

    left_parts, right_parts : [(body name, (vertices (n, 3), faces (m, 3)))]
        The bodies each lies on, in ``expand_lies_on`` order (the concatenation its action
        lines' surface points refer to).
    mirror : :class:`faceforge.geometry.mirror.Mirror`
    exact : set of str
        Bodies already built as mirror images of their twins (face-by-face mapping).
    """
    from faceforge.anatomy.muscles.muscle import _build

    if left.kind != "linear":
        raise ValueError(f"muscle {left.name!r}: only linear muscles are mirrored, not a {left.kind}")
    lines = {k: replace(line, points=_mirror_points(line.points, left_parts, right_parts, mirror, exact))
             for k, line in left.lines.items()}
    v = np.vstack([m[0] for _, m in right_parts])
    f = np.vstack([m[1] + o for (_, m), o in zip(right_parts, np.cumsum([0] + [len(m[0]) for _, m in right_parts]))])
    m = _build(name, "linear", left.topology, lines, v, f, left.thickness, dict(left.stiffness),
               lies_on=tuple(lies_on), layer=left.layer, active=left.active, max_contraction=left.max_contraction)
    return replace(m, faces=np.ascontiguousarray(left.faces[:, ::-1]))


def symmetric_loop(line, parts, mirror, exact: set):
    """A closed action line (a sphincter's loop) of a muscle that is its own mirror image, made
    symmetric. The loop's two points nearest the plane, a quarter of the loop or more apart, split
    it into two arcs; the arc on the subject's right of the plane (against ``mirror.normal``, on
    average) is kept, the other is replaced by the kept arc's mirror images in reverse order
    (:func:`_mirror_points`), and each split point by the closest point of the bodies that are
    their own mirror images to its foot on the plane (:func:`_on_plane`). The loop keeps its sense and starts at the split point it reached first
    from its old start (a sphincter's two loops start at corresponding points, and still do),
    so that sampled at regular arc length from there (Eq. 3) sample ``k`` and sample ``-k`` are
    mirror images.

    Which half is kept matters, as it decides which muscle each mouth corner's loop lies on
    (outermost projection): on MakeHuman the left half puts the corner on the risorius, and the
    zygomaticus then lifts its corner 30 MW at c = 1 (208 on the unsymmetrised rig); the right
    half keeps it on the zygomaticus (120 MW).

    line : ActionLine (closed) on the concatenated ``parts`` [(body name, (v, f))], which hold
    both twins of every body pair it lies on. A loop of fewer than 8 points is returned as is.
    """
    v = np.vstack([m[0] for _, m in parts])
    f = np.vstack([m[1] + o for (_, m), o in zip(parts, np.cumsum([0] + [len(m[0]) for _, m in parts]))])
    pos = line.positions(v, f)
    n = len(pos)
    if n < 8:
        return line
    side = mirror.side(pos)
    i0 = int(np.argmin(np.abs(side)))
    gap = np.minimum((np.arange(n) - i0) % n, (i0 - np.arange(n)) % n)
    i1 = int(np.argmin(np.where(gap >= n // 4, np.abs(side), np.inf)))
    arc_a = (i0 + 1 + np.arange((i1 - i0 - 1) % n)) % n     # i0 -> i1 in the loop's sense
    arc_b = (i1 + 1 + np.arange((i0 - i1 - 1) % n)) % n     # i1 -> i0
    if not len(arc_a) or not len(arc_b):
        return line
    first, last, kept = (i0, i1, arc_a) if side[arc_a].mean() < side[arc_b].mean() else (i1, i0, arc_b)
    kept = kept[side[kept] < 0.0]   # a point next to a split point may lie just across the plane
    if not len(kept):
        return line
    keep = line.points.take(kept)
    image = _mirror_points(keep.take(np.arange(len(kept))[::-1]), parts, parts, mirror, exact)
    loop = [_on_plane(line.points.take([first]), parts, v, f, mirror), keep,
            _on_plane(line.points.take([last]), parts, v, f, mirror), image]
    if last < first:   # start at the split point the loop reaches first from its old start
        loop = loop[2:] + loop[:2]
    return replace(line, points=SurfacePoints.concatenate(loop))


def symmetric_sheet_lines(lines: dict, parts, mirror, exact: set) -> dict:
    """The action lines {A0..A3: ActionLine} of a linear muscle that is its own mirror image
    (the mentalis, across the chin), made symmetric: A2 the mirror image of A0, and the origin
    and insertion (A3, A1, running from A0's side to A2's) each its half on A0's side, a point
    on the plane and that half's mirror image in reverse order. Built from its own lines, the
    mentalis was not: its origin row lay all on one side of the plane (MakeHuman, 0.02 ES0
    apart from its mirror image at the chin), and the depressors that lie on it followed.
    ``parts`` [(body name, (v, f))] as for :func:`symmetric_loop`."""
    v = np.vstack([m[0] for _, m in parts])
    f = np.vstack([m[1] + o for (_, m), o in zip(parts, np.cumsum([0] + [len(m[0]) for _, m in parts]))])
    start = mirror.side(lines["A0"].points.take([0]).positions(v, f))[0]
    out = dict(lines, A2=replace(lines["A2"], points=_mirror_points(lines["A0"].points, parts, parts, mirror, exact)))
    for key in ("A1", "A3"):
        pts = lines[key].points
        side = mirror.side(pts.positions(v, f)) * np.sign(start)
        across = np.flatnonzero(side <= 0.0)
        kept = np.arange(across[0] if len(across) else len(side))   # the leading run on A0's side
        if not len(kept) or start == 0.0:
            continue
        mid = _on_plane(pts.take([int(np.argmin(np.abs(side)))]), parts, v, f, mirror)
        keep = pts.take(kept)
        image = _mirror_points(keep.take(np.arange(len(kept))[::-1]), parts, parts, mirror, exact)
        out[key] = replace(lines[key], points=SurfacePoints.concatenate([keep, mid, image]))
    return out


def _on_plane(point: SurfacePoints, parts, v, f, mirror) -> SurfacePoints:
    """The closest point, on the midline of the bodies of ``parts`` that are their own mirror
    images (the bone, a midline muscle: :func:`plane_section_closest`), to the foot on the plane
    of one surface point of the concatenated mesh (v, f): a point on the midline that follows
    either twin would move one way for the left muscle and another for the right one.

    The closest point of the whole body is not used: where the body's midline is a groove (the
    maxilla between the incisor roots), the two closest points lie left and right of the plane
    at equal distance, and the closest-point search returned one of them by round-off (MakeHuman:
    the orbicularis oris' outer loop split 0.45 mm right of the plane on an AVX-512 machine, its
    samples then 0.8 mm from their mirror images and the solver's mirror pairing off)."""
    starts = np.cumsum([0] + [len(m[1]) for _, m in parts])
    p = mirror.onto_plane(point.positions(v, f))
    best = None
    for (name, (bv, bf)), s0 in zip(parts, starts):
        if mirrored_name(name) != name:
            continue
        hit = plane_section_closest(p[0], bv, bf, mirror)
        if hit is None:   # the body does not reach the plane
            sp = project_to_surface(p, bv, bf)
            hit = (float(np.linalg.norm(sp.positions(bv, bf) - p)), sp)
        if best is None or hit[0] < best[0]:
            best = (hit[0], SurfacePoints(hit[1].face_ids + s0, hit[1].bary))
    return best[1] if best is not None else project_to_surface(p, v, f)


def plane_section_closest(p: np.ndarray, vertices: np.ndarray, faces: np.ndarray, mirror):
    """``(distance, SurfacePoints (1,))``: the point of the mesh's section by the mirror plane
    (the segments where its faces cross the plane) closest to ``p (3,)``; None when no face
    crosses the plane. The point lies on the plane and on the surface, so on a body that is its
    own mirror image it is its own mirror image: unlike the closest point of the whole surface,
    it does not depend on how a tie between two mirrored closest points is broken."""
    v = np.asarray(vertices, dtype=FLOAT)
    f = np.asarray(faces)
    s = mirror.side(v)[f]                                  # (m, 3) sides of each face's corners
    cross = np.flatnonzero((s.min(axis=1) <= 0.0) & (s.max(axis=1) >= 0.0))
    if not len(cross):
        return None
    eye = np.eye(3)
    ends = []   # per crossing face, up to two barycentric end points of its section
    for k in cross:
        pts = [eye[a] for a in range(3) if s[k, a] == 0.0]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            if s[k, a] * s[k, b] < 0.0:
                t = s[k, a] / (s[k, a] - s[k, b])
                pts.append((1.0 - t) * eye[a] + t * eye[b])
        # at most three points (a face lying in the plane: one of its edges stands for it)
        ends.append((pts[0], pts[-1]))
    ba = np.array([e[0] for e in ends])
    bb = np.array([e[1] for e in ends])
    tri = v[f[cross]]
    a = np.einsum("ij,ijk->ik", ba, tri)
    b = np.einsum("ij,ijk->ik", bb, tri)
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.divide(np.einsum("ij,ij->i", p - a, ab), den, out=np.zeros(len(den)), where=den > 0), 0.0, 1.0)
    q = a + t[:, None] * ab
    d = np.linalg.norm(q - p, axis=1)
    j = int(np.argmin(d))
    w = (1.0 - t[j]) * ba[j] + t[j] * bb[j]
    return float(d[j]), SurfacePoints(np.array([cross[j]], dtype=INT), w[None] / w.sum())


def symmetric_ring_faces(muscle) -> np.ndarray:
    """Faces ``(m, 3)`` of a sphincter whose loops are symmetric (:func:`symmetric_loop`: sample
    ``k`` mirrors sample ``-k``) with its cells split as mirror images: each cell of the first
    half keeps its diagonal (:func:`faceforge.anatomy.muscles.hexmesh.cell_diagonals`), its
    mirror cell takes the mirrored one. Split all alike (the default), the ring's triangles
    run one way on the left and the other way on the right, and so do its bending and area
    constraints. The rest positions do not change (the constraints' rest values come from them)."""
    from faceforge.anatomy.muscles.hexmesh import _faces, cell_diagonals, signed_volume

    h, w = muscle.topology.h, muscle.topology.w
    flip = cell_diagonals(h, w, True, muscle.rest_positions[: h * w])
    i, j = np.meshgrid(np.arange(h), np.arange(w - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    image = ((-i - 1) % h) * (w - 1) + j
    first = i < h // 2
    flip = flip.copy()
    flip[image[first]] = ~flip[first]
    faces = _mirror_walls(_faces(h, w, True, flip), h, w)
    if signed_volume(muscle.rest_positions, faces) < 0:
        faces = faces[:, ::-1].copy()
    return faces


def _mirror_walls(faces: np.ndarray, h: int, w: int) -> np.ndarray:
    """A ring's faces (:func:`faceforge.anatomy.muscles.hexmesh._faces`) with the wall quads of
    its second half split as the mirror images of the first half's (sample k <-> -k): the
    walls split every quad along the same diagonal, so the two halves' wall triangles (and
    their bending and area constraints) did not pair up."""
    n = h * w
    part = np.array([(i * w + np.arange(w)) for i in range(h)])
    image = np.concatenate([part[(-np.arange(h)) % h].ravel(), part[(-np.arange(h)) % h].ravel() + n])
    nwall = len(faces) - 2 * (2 * h * (w - 1))   # two sheets of 2 h (w - 1) triangles, then the walls
    body, wall = faces[:len(faces) - nwall], faces[len(faces) - nwall:]
    half = nwall // 2
    first, second = wall[:half], wall[half:]   # triangles (b, a, a+n) and (b, a+n, b+n) per quad
    b, a = first[:, 0], first[:, 1]
    row = np.minimum(a % n // w, b % n // w)
    wrap = np.abs(a % n // w - b % n // w) > 1
    row = np.where(wrap, h - 1, row)
    keep = row < h // 2
    out_first, out_second = first.copy(), second.copy()
    quads = {}
    for k in np.flatnonzero(keep):   # each kept quad's diagonal, mirrored
        quads[frozenset(image[[b[k], a[k], a[k] + n, b[k] + n]].tolist())] = (image[a[k] + n], image[b[k]])
    for k in np.flatnonzero(~keep):
        d = quads.get(frozenset([b[k], a[k], a[k] + n, b[k] + n]))
        if d is None or set(d) == {a[k] + n, b[k]}:
            continue
        # the other diagonal (a, b + n): triangles (b, a, b + n) and (a, a + n, b + n)
        out_first[k] = (b[k], a[k], b[k] + n)
        out_second[k] = (a[k], a[k] + n, b[k] + n)
    return np.concatenate([body, out_first, out_second]).astype(faces.dtype)


def particle_mirror(muscles, firsts, n_particles: int, mirror, tol: float) -> np.ndarray:
    """Each particle's mirror partner ((n_particles,) int) in one layer's PBD model holding
    ``muscles`` (first particles ``firsts``): a twin's particle k <-> its twin's particle k;
    in a muscle that is its own mirror image, the sphincter's sample k <-> sample -k and a
    sheet's column j <-> column w - 1 - j, in each of its two sheets. A muscle whose rest
    particles do not match their partners' mirror images within ``tol`` (mesh units), and
    a twin outside the layer, keep their particles to themselves."""
    out = np.arange(n_particles, dtype=np.int64)
    first = {m.name: int(f) for m, f in zip(muscles, firsts)}
    for m in muscles:
        n = len(m.rest_positions)
        twin = mirrored_name(m.name)
        if twin != m.name:
            if twin not in first:
                continue
            other = next(x for x in muscles if x.name == twin)
            local, rest = np.arange(n), other.rest_positions
        else:
            h, w = m.topology.h, m.topology.w
            i, j = np.divmod(np.arange(h * w), w)
            sheet = ((-i) % h) * w + j if m.kind == "sphincter" else i * w + (w - 1 - j)
            if 2 * h * w != n:
                continue
            local, rest = np.concatenate([sheet, sheet + h * w]), m.rest_positions
        if len(rest) != n or np.linalg.norm(mirror(m.rest_positions) - rest[local], axis=1).max() > tol:
            continue
        out[first[m.name]:first[m.name] + n] = first[twin] + local
    return out
