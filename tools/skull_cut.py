"""The fused template skull cut into cranium and mandible (step 2 of ``build_template.py``).

A minimum cut on the dual graph of the mesh (faces = nodes, shared edges = arcs of capacity =
edge length) between the chin and the vault, allowed only inside the dental arch and the rami;
each cut loop closed by an ear-clipped cap in its best-fit plane. Lengths are the source skull's
units (YahooJAPAN frame, x-centred, skull height 13.9).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import trimesh


def jaw_min_cut(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Boolean (m,) mask of the mandible's faces: minimum edge-length cut chin | vault.

    Search regions (source skull units, x-centred YahooJAPAN frame, skull height 13.9):
    the dental arch (|x| < 2.8, 1 < z, 2.6 < y < 5.2) and the rami (|x| > 2.4,
    -2.5 < z < 3.4, 4.4 < y < 6.6). Arcs outside them cannot be cut.
    """
    c = v[f].mean(axis=1)
    ax = np.abs(c[:, 0])
    teeth = (ax < 2.8) & (c[:, 2] > 1.0) & (c[:, 1] > 2.6) & (c[:, 1] < 5.2)
    rami = (ax > 2.4) & (c[:, 2] > -2.5) & (c[:, 2] < 3.4) & (c[:, 1] > 4.4) & (c[:, 1] < 6.6)
    region = teeth | rami
    mesh = trimesh.Trimesh(v, f, process=False)
    adj, edges = mesh.face_adjacency, mesh.face_adjacency_edges
    length = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    cuttable = region[adj[:, 0]] & region[adj[:, 1]]
    # steer the cut: in the dental arch towards the occlusal line seen on the full-resolution
    # skull (incisal edges at y = 3.4, sloping down 0.15 per unit backwards); in the rami
    # upwards, to where the condyles and coronoid processes meet the temporal bone
    mid = v[edges].mean(axis=1)
    y_occ = 3.4 - 0.15 * (5.6 - mid[:, 2])
    w_teeth = 1.0 + ((mid[:, 1] - y_occ) / 0.2) ** 2
    w_rami = 1.0 + (np.maximum(5.7 - mid[:, 1], 0.0) / 0.3) ** 2
    weight = np.where(np.abs(mid[:, 0]) < 2.6, w_teeth, w_rami)
    big = 10**7
    cap = np.where(cuttable, np.minimum(np.round(length * weight * 1000), big - 1).astype(np.int64) + 1, big)
    n = len(f)
    src, snk = n, n + 1
    chin = np.flatnonzero(c[:, 1] < 1.0)
    vault = np.flatnonzero(c[:, 1] > 8.0)
    rows = np.r_[adj[:, 0], adj[:, 1], np.full(len(chin), src), vault]
    cols = np.r_[adj[:, 1], adj[:, 0], chin, np.full(len(vault), snk)]
    caps = np.r_[cap, cap, np.full(len(chin) + len(vault), 10 * big)].astype(np.int32)
    graph = sp.csr_matrix((caps, (rows, cols)), shape=(n + 2, n + 2))
    flow = csgraph.maximum_flow(graph, src, snk).flow
    residual = (graph - flow).tocsr()
    residual.data[residual.data < 0] = 0
    residual.eliminate_zeros()
    reach = csgraph.breadth_first_order(residual, src, directed=True, return_predecessors=False)
    mask = np.zeros(n + 2, dtype=bool)
    mask[reach] = True
    return mask[:n]


def boundary_loops(f: np.ndarray) -> list[np.ndarray]:
    """Boundary loops of a manifold mesh, each ordered along its faces' half-edges."""
    half = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    keys = {tuple(e) for e in half.tolist()}
    nxt = {a: b for a, b in half.tolist() if (b, a) not in keys}
    loops, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop, cur = [], start
        while cur not in seen:
            seen.add(cur)
            loop.append(cur)
            cur = nxt[cur]
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _ear_clip(p2: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangulate a simple polygon (k,2) given counter-clockwise; indices into p2."""
    idx = list(range(len(p2)))
    tris = []

    def cross(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    guard = 0
    while len(idx) > 3 and guard < 10000:
        guard += 1
        best, best_q = None, -np.inf
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = p2[i0], p2[i1], p2[i2]
            if cross(a, b, c) <= 1e-12:
                continue
            inside = False
            for j in idx:
                if j in (i0, i1, i2):
                    continue
                q = p2[j]
                if cross(a, b, q) >= 0 and cross(b, c, q) >= 0 and cross(c, a, q) >= 0:
                    inside = True
                    break
            if inside:
                continue
            # prefer well-shaped ears: the smallest angle of the triangle
            e = [np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c)]
            quality = cross(a, b, c) / max(max(e) ** 2, 1e-30)
            if quality > best_q:
                best, best_q = k, quality
        if best is None:  # numerically degenerate remainder: fan it
            break
        k = best
        tris.append((idx[k - 1], idx[k], idx[(k + 1) % len(idx)]))
        idx.pop(k)
    for k in range(1, len(idx) - 1):
        tris.append((idx[0], idx[k], idx[k + 1]))
    return tris


def cap_loop(v: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """Faces (k,3) closing ``loop`` (ordered along the mesh's half-edges), planar-projected.

    The cap runs each boundary edge in the opposite direction to the existing face, so the
    closed mesh stays consistently oriented.
    """
    p = v[loop]
    centre = p.mean(0)
    _, _, vt = np.linalg.svd(p - centre)
    e1, e2 = vt[0], vt[1]
    p2 = np.c_[(p - centre) @ e1, (p - centre) @ e2]
    rev = loop[::-1]
    p2r = p2[::-1]
    area = 0.5 * np.sum(p2r[:, 0] * np.roll(p2r[:, 1], -1) - np.roll(p2r[:, 0], -1) * p2r[:, 1])
    if area < 0:  # make the reversed loop counter-clockwise in (e1, e2) by flipping e2
        p2r = p2r * [1.0, -1.0]
    # triangles follow the reversed loop's index order, so their boundary edges run
    # opposite to the existing faces whatever the 2D frame's handedness
    tris = np.array(_ear_clip(p2r), dtype=np.int64)
    return rev[tris]


def split_skull(v: np.ndarray, f: np.ndarray):
    """Cut the fused skull; return (cranium (v,f), mandible (v,f), cut loops {name: (k,3)})."""
    jaw = jaw_min_cut(v, f)
    parts, loops = {}, {}
    for name, faces in (("cranium", f[~jaw]), ("mandible", f[jaw])):
        used = np.unique(faces)
        remap = -np.ones(len(v), dtype=np.int64)
        remap[used] = np.arange(len(used))
        pv, pf = v[used], remap[faces]
        caps = []
        for loop in boundary_loops(pf):
            caps.append(cap_loop(pv, loop))
            if name == "mandible":
                loops[f"loop{len(loops)}"] = pv[loop]
        pf = np.concatenate([pf] + caps)
        mesh = trimesh.Trimesh(pv, pf, process=False)
        if mesh.volume < 0:
            mesh.invert()
        parts[name] = (np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64))
    return parts["cranium"], parts["mandible"], loops
