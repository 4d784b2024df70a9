"""Make unseen-head variants of the samples (issue 25/26 robustness, docs/notes/robust19.md).

    python tools/make_variants.py OUT_DIR [--surprise FRAME.obj]

Writes OBJ files (no landmark file beside them) into OUT_DIR:

- ``mh_low.obj``: MakeHuman decimated by shortest-edge collapse to ~2,000 vertices (triangles;
  ``cluster_decimate``, vertex clustering, is kept: it makes non-manifold edges, which fit refuses);
- ``ict_sub1.obj`` / ``ict_sub2.obj``: ICT with each quad split into four (45k / 180k vertices);
- ``mh_scan.obj``: MakeHuman with 0.4 mm Gaussian noise and the neck cut at a slanted plane;
- ``mh_holes.obj``: MakeHuman with a few random patches of faces removed;
- ``mh_turned.obj``: MakeHuman turned 20 deg yaw and 15 deg pitch;
- ``mh_px.obj``: MakeHuman facing +X (a quarter turn about +Y);
- ``mh_open.obj``: with ``--surprise``, that frame (an OBJ of the user's quads) as a new neutral.

Polygons are kept (:func:`faceforge.io.mesh.read_obj_polygons`; written by :func:`faceforge.io.export_obj.write_obj`).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from faceforge.io.export_obj import write_obj
from faceforge.io.mesh import read_obj_polygons

ROOT = Path(__file__).resolve().parents[1]
MH = ROOT / "samples/makehuman/mh_head_default.obj"
ICT = ROOT / "samples/ict/ict_face_headneck_neutral.obj"
MM_PER_UNIT_MH = 100.0   # MakeHuman: decimetres
RNG = np.random.default_rng(19)


def read_obj(path):
    """Vertices (n, 3) float64 and faces as a list of int arrays (0-based, polygons kept) of an OBJ."""
    verts, polygons = read_obj_polygons(path)
    return verts, [np.asarray(f) for f in polygons]


def compact(verts, faces):
    """Drop unused vertices; renumber faces."""
    used = np.unique(np.concatenate(faces))
    remap = -np.ones(len(verts), int)
    remap[used] = np.arange(len(used))
    return verts[used], [remap[f] for f in faces]


def rotation(yaw_deg, pitch_deg):
    """(3, 3) rotation: pitch about +X (chin down for positive), then yaw about +Y."""
    a, b = np.radians(yaw_deg), np.radians(pitch_deg)
    ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return ry @ rx


def cluster_decimate(verts, faces, target):
    """Vertex clustering on a grid whose cell is chosen to keep about ``target`` vertices.

    Returns vertices (k, 3) (each cluster's mean) and triangles (list of (3,) arrays) with
    collapsed and duplicate triangles removed.
    """
    tris = [t for f in faces for t in ([f[0], f[i], f[i + 1]] for i in range(1, len(f) - 1))]
    tris = np.asarray(tris)
    ext = verts.max(0) - verts.min(0)
    lo, hi = 1e-4 * ext.max(), ext.max()
    for _ in range(40):                       # bisection on the cell size
        cell = np.sqrt(lo * hi)
        keys = np.floor((verts - verts.min(0)) / cell).astype(np.int64)
        _, label = np.unique(keys, axis=0, return_inverse=True)
        k = label.max() + 1
        if abs(k - target) < 0.03 * target:
            break
        lo, hi = (cell, hi) if k > target else (lo, cell)
    label = label.ravel()
    cnt = np.bincount(label)
    new = np.stack([np.bincount(label, verts[:, d]) / cnt for d in range(3)], 1)
    t = label[tris]
    ok = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
    t = t[ok]
    _, first = np.unique(np.sort(t, 1), axis=0, return_index=True)
    t = t[np.sort(first)]
    return compact(new, list(t))


def collapse_decimate(verts, faces, target):
    """Shortest-edge collapse to about ``target`` vertices (triangles out; a stand-in for quadric
    decimation, which the installed trimesh lacks). An edge collapses to its midpoint (to the
    boundary vertex when one end is on the boundary, never two boundary vertices across the
    inside) only if its ends share exactly the opposite vertices of its faces (the link
    condition: the surface stays a manifold) and no face around turns over."""
    import heapq

    tris = np.asarray([t for f in faces for t in ([f[0], f[i], f[i + 1]] for i in range(1, len(f) - 1))])
    v = verts.copy()
    alive = np.ones(len(tris), bool)
    vf = [set() for _ in range(len(v))]
    for i, t in enumerate(tris):
        for a in t:
            vf[a].add(i)

    def nbrs(a):
        return {b for i in vf[a] for b in tris[i]} - {a}

    def boundary(a):
        cnt = {}
        for i in vf[a]:
            for b in tris[i]:
                if b != a:
                    cnt[b] = cnt.get(b, 0) + 1
        return any(c == 1 for c in cnt.values())

    def normal(t, p):
        return np.cross(p[t[1]] - p[t[0]], p[t[2]] - p[t[0]])

    heap = [(np.linalg.norm(v[a] - v[b]), a, b) for t in tris for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))]
    heapq.heapify(heap)
    n_alive = len(v)
    gone = np.zeros(len(v), bool)
    while n_alive > target and heap:
        d, a, b = heapq.heappop(heap)
        if gone[a] or gone[b] or abs(np.linalg.norm(v[a] - v[b]) - d) > 1e-12:
            continue
        shared = vf[a] & vf[b]
        if not shared or nbrs(a) & nbrs(b) != {c for i in shared for c in tris[i]} - {a, b}:
            continue
        ba, bb = boundary(a), boundary(b)
        if ba and bb and len(shared) != 1:
            continue
        p = v[a] if ba and not bb else v[b] if bb and not ba else 0.5 * (v[a] + v[b])
        trial = v.copy()
        trial[a] = trial[b] = p
        ok = True
        for i in (vf[a] | vf[b]) - shared:
            if normal(tris[i], trial) @ normal(tris[i], v) <= 0:
                ok = False
                break
        if not ok:
            continue
        v[a] = p
        for i in shared:
            alive[i] = False
            for c in tris[i]:
                vf[c].discard(i)
        for i in list(vf[b]):
            tris[i][tris[i] == b] = a
            vf[a].add(i)
        vf[b] = set()
        gone[b] = True
        n_alive -= 1
        for c in nbrs(a):
            heapq.heappush(heap, (np.linalg.norm(v[a] - v[c]), a, c))
    return compact(v, list(tris[alive]))


def subdivide_quads(verts, faces):
    """Split each polygon into quads at its centroid and edge midpoints (Catmull-Clark topology,
    positions not smoothed: the surface is unchanged). Returns vertices and quad faces."""
    verts = list(map(np.asarray, verts))
    edge_id = {}
    out = []
    n = len(verts)
    pts = [v for v in verts]

    def mid(a, b):
        key = (a, b) if a < b else (b, a)
        if key not in edge_id:
            edge_id[key] = len(pts)
            pts.append(0.5 * (pts[a] + pts[b]))
        return edge_id[key]

    for f in faces:
        c = len(pts)
        pts.append(np.mean([pts[i] for i in f], axis=0))
        k = len(f)
        for i in range(k):
            a, b, p = f[i], f[(i + 1) % k], f[i - 1]
            out.append(np.array([a, mid(a, b), c, mid(p, a)]))
    del n
    return np.asarray(pts), out


def neck_cut(verts, faces, normal, point):
    """Keep faces with every vertex on the positive side of the plane (normal, point)."""
    side = (verts - point) @ normal > 0
    return compact(verts, [f for f in faces if side[f].all()])


def holes(verts, faces, n_holes, radius, avoid=None):
    """Remove every face within ``radius`` of ``n_holes`` random face centroids."""
    cen = np.array([verts[f].mean(0) for f in faces])
    pick = RNG.choice(len(faces), n_holes, replace=False)
    drop = np.zeros(len(faces), bool)
    for p in pick:
        drop |= np.linalg.norm(cen - cen[p], axis=1) < radius
    return compact(verts, [f for f, d in zip(faces, drop) if not d])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("--surprise", type=Path)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    mv, mf = read_obj(MH)
    iv, iff = read_obj(ICT)

    v, f = collapse_decimate(mv, mf, 2000)
    write_obj(a.out / "mh_low.obj", v, f, "MakeHuman, shortest-edge collapse to ~2000 vertices")
    v, f = subdivide_quads(iv, iff)
    write_obj(a.out / "ict_sub1.obj", v, f, "ICT, quads split in four")
    v2, f2 = subdivide_quads(v, f)
    write_obj(a.out / "ict_sub2.obj", v2, f2, "ICT, quads split in four twice")

    noisy = mv + RNG.normal(0, 0.4 / MM_PER_UNIT_MH, mv.shape)
    lo, hi = mv.min(0), mv.max(0)
    nrm = np.array([0.2, 1.0, 0.45])
    nrm /= np.linalg.norm(nrm)   # rises toward the back and to the right: a scan's slanted neck cut
    v, f = neck_cut(noisy, mf, nrm, lo + (hi - lo) * [0.5, 0.12, 0.8])
    write_obj(a.out / "mh_scan.obj", v, f, "MakeHuman, 0.4 mm noise, neck cut at a slanted plane")
    v, f = holes(mv, mf, 6, 0.06)
    write_obj(a.out / "mh_holes.obj", v, f, "MakeHuman with 6 holes of 6 mm radius")

    c = mv.mean(0)
    write_obj(a.out / "mh_turned.obj", (mv - c) @ rotation(20, 15).T + c, mf,
              "MakeHuman turned 20 deg yaw, 15 deg pitch")
    write_obj(a.out / "mh_px.obj", mv @ rotation(90, 0).T, mf, "MakeHuman facing +X")
    if a.surprise:
        sv, sf = read_obj(a.surprise)
        write_obj(a.out / "mh_open.obj", sv, sf, f"MakeHuman, {a.surprise.name} as a neutral")
    for p in sorted(a.out.glob("*.obj")):
        vv, ff = read_obj(p)
        print(f"{p.name}: {len(vv)} vertices, {len(ff)} faces, bbox {np.ptp(vv, 0).round(3)}")


if __name__ == "__main__":
    main()
