"""Build ``templates/skull/`` (cranium, mandible, FDP landmarks, jaw axes) from the shared assets.

Reproducible: ``python tools/build_template.py [--assets /work/shared/assets] [--out templates/skull]``
rewrites ``cranium.obj``, ``mandible.obj``, ``landmarks.yaml`` and ``jaw.yaml`` byte for byte
with the same numpy and scipy (no randomness); another release may change a number in its last
printed decimal (numpy 2.4 moved 73 of 7,760 vertices by 1e-6). Only numpy, scipy, trimesh and PyYAML are used (all runtime dependencies);
the build does not need any extra package.

Steps
-----
1. **Skull.** The YahooJAPAN skull (``anatomy/skull-yahoojapan/skull_low_resolution.obj``,
   CC BY 3.0; 5,154 vertices, one closed surface, Y up, face +Z, mandible fused to the
   cranium with the teeth in occlusion) is welded, its midsagittal plane (found by
   mirror-ICP) moved to x = 0, and the shape symmetrised by averaging each vertex with
   the mirror image of its mirrored closest surface point. Then its +x half is kept and
   mirrored with the mirror-image triangulation, welded at x = 0
   (:func:`faceforge.geometry.mirror_mesh.mirror_half`): both bones are their own mirror
   images vertex for vertex, so a fit that moves vertex pairs alike keeps them symmetric
   (issue 25). The placement (step 3) is fitted on the shape before this step, so the
   template frame did not move.
2. **Mandible** (`skull_cut.py`). The fused skull is split with a minimum cut on the dual graph of the
   mesh (faces = nodes, shared edges = arcs of capacity = edge length) between the chin
   (source) and the vault (sink). Arcs may only be cut inside two search regions around
   the known fusions: the dental arch (teeth in occlusion) and the rami (condylar necks,
   coronoid processes under the zygomatic arches). The minimum cut is the shortest set of
   closed curves separating the jaw from the cranium: it runs around the thinnest necks,
   i.e. through the occlusal contact and the condylar necks. Each cut loop is closed on
   both sides by an ear-clipped cap in the loop's best-fit plane, so both bones are closed
   and consistently oriented (outward normals).
3. **Placement.** A similarity transform (uniform scale, rotation about x, translation in
   y and z; x stays the midsagittal plane) puts the skull into the ICT-FaceKit head
   (``heads/ict/``, cm): eight bony points found on the midline profile and the lateral
   extremes of the skull are matched, in the least-squares sense, to the corresponding
   skin points moved inward along the skin normal by the soft-tissue depth of
   ``tissue-depth/`` (Rhine 1983). The template therefore lives in the ICT head's frame:
   **centimetres, life size**, +Y up, face +Z, subject's left +X, midsagittal plane x = 0.
   Optionally (``--dental-warp``, experimental, off for the committed template) the dental
   region is then moved down onto the lips' contact line (:func:`dental_warp`): a similarity
   leaves the incisal edge 1.6 cm above ICT's stomion.
4. **Landmarks.** For each chosen FDP of the ICT head a ray is cast from the skin point
   inward (against the smoothed skin normal) and the first hit on the prescribed bone is
   the landmark (closest bone point when the ray misses or exits through an opening,
   e.g. the orbit). Right-side landmarks are the exact mirror images of the left ones
   (the skull is symmetric). Upper-lip FDPs are put on the maxilla (cranium), lower-lip
   FDPs on the mandible, so mandible landmarks move with the jaw.
5. **Jaw.** Pitch axis through the centres of the two condylar cut loops (left-right);
   yaw axis vertical through their midpoint; protrusion direction = the forward direction
   of the occlusal plane (best-fit plane of the dental cut) in the midsagittal plane.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import trimesh
import yaml
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from faceforge.geometry.mirror_mesh import mirror_half

sys.path.insert(0, str(Path(__file__).resolve().parent))
from skull_cut import split_skull  # noqa: E402  (step 2, beside this file)

ROOT = Path(__file__).resolve().parents[1]

#: FDP -> (bone, soft-tissue depth used in the placement fit or None)
LANDMARK_BONES = {
    # chin and jaw corners (mandible)
    "2.1": "mandible", "2.10": "mandible", "2.13": "mandible", "2.14": "mandible",
    # inner lip: upper lip on the maxilla, lower lip on the mandible, corners on the maxilla
    "2.2": "cranium", "2.6": "cranium", "2.7": "cranium", "2.4": "cranium", "2.5": "cranium",
    "2.3": "mandible", "2.8": "mandible", "2.9": "mandible",
    # outer lip
    "8.1": "cranium", "8.5": "cranium", "8.6": "cranium", "8.9": "cranium", "8.10": "cranium",
    "8.3": "cranium", "8.4": "cranium",
    "8.2": "mandible", "8.7": "mandible", "8.8": "mandible",
    # eye corners on the orbit rims
    "3.7": "cranium", "3.8": "cranium", "3.11": "cranium", "3.12": "cranium",
    # brows on the brow ridge
    "4.1": "cranium", "4.2": "cranium", "4.3": "cranium", "4.4": "cranium", "4.5": "cranium", "4.6": "cranium",
    # cheeks on the maxilla / zygomatic bone
    "5.1": "cranium", "5.2": "cranium", "5.3": "cranium", "5.4": "cranium",
    # nose: alae and base on the rim of the nasal aperture / anterior nasal spine
    "9.1": "cranium", "9.2": "cranium", "9.4": "cranium", "9.5": "cranium", "9.15": "cranium",
    # ears: root of the zygomatic arch in front of the auditory meatus
    "10.9": "cranium", "10.10": "cranium",
    # hairline, top and back of the skull on the frontal / parietal / occipital bone
    "11.1": "cranium", "11.2": "cranium", "11.3": "cranium", "11.4": "cranium", "11.6": "cranium",
}

#: FDPs whose ray is cast straight back (-Z) instead of against the skin normal: the
#: skin normal at the lips and the nose base points up or down along the lip surface
STRAIGHT_BACK = {"2.2", "2.3", "2.4", "2.5", "2.6", "2.7", "2.8", "2.9",
                 "8.1", "8.2", "8.3", "8.4", "8.5", "8.6", "8.7", "8.8", "8.9", "8.10",
                 "9.1", "9.2", "9.4", "9.5", "9.15"}


# ----------------------------------------------------------------------------- loading
def load_welded(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an OBJ and weld coincident vertices: (v (n,3) float64, f (m,3) int64)."""
    m = trimesh.load(path, force="mesh")
    m = trimesh.Trimesh(m.vertices, m.faces, process=True)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def mirror_plane_offset(v: np.ndarray, iterations: int = 30) -> float:
    """x of the midsagittal plane: rigid ICP of the x-mirrored points onto the points.

    The plane halfway between each point and its ICP-aligned mirror image is averaged.
    """
    tree = cKDTree(v)
    cur = v * [-1.0, 1.0, 1.0]
    for _ in range(iterations):
        _, idx = tree.query(cur)
        p, q = cur, v[idx]
        pc, qc = p.mean(0), q.mean(0)
        u, _, vt = np.linalg.svd((p - pc).T @ (q - qc))
        d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
        cur = (p - pc) @ (vt.T @ d @ u.T).T + qc
    return float(((v + cur) / 2.0)[:, 0].mean())


def symmetrise(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Average each vertex with the mirror of the closest surface point to its mirror image."""
    mesh = trimesh.Trimesh(v, f, process=False)
    mirrored = v * [-1.0, 1.0, 1.0]
    closest, _, _ = trimesh.proximity.closest_point(mesh, mirrored)
    return (v + closest * [-1.0, 1.0, 1.0]) / 2.0


# ----------------------------------------------------------------------------- placement
def _rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def apply_similarity(params, points: np.ndarray) -> np.ndarray:
    """p' = s R_x(a) p + (0, ty, tz) for params (s, a, ty, tz)."""
    s, a, ty, tz = params
    return s * points @ _rot_x(a).T + np.array([0.0, ty, tz])


def _midline(v: np.ndarray, half_width: float) -> np.ndarray:
    return v[np.abs(v[:, 0]) < half_width]


def skull_points(v: np.ndarray) -> dict[str, np.ndarray]:
    """Bony reference points on the x-centred source skull (source units), by extremes."""
    mid = _midline(v, 0.3)
    pts = {}
    pts["vertex"] = mid[np.argmax(mid[:, 1])]
    back = mid[mid[:, 1] > 6.0]
    pts["opisthocranion"] = back[np.argmin(back[:, 2])]
    brow = mid[(mid[:, 1] > 7.5) & (mid[:, 1] < 10.0)]
    pts["glabella"] = brow[np.argmax(brow[:, 2])]
    chin = mid[mid[:, 1] < 2.0]
    pts["pogonion"] = chin[np.argmax(chin[:, 2])]
    pts["menton"] = mid[np.argmin(mid[:, 1])]
    top = v[v[:, 1] > 8.0]
    pts["euryon"] = top[np.argmax(top[:, 0])]
    arch = v[(v[:, 1] > 5.0) & (v[:, 1] < 7.0) & (v[:, 2] > -1.0)]
    pts["zygion"] = arch[np.argmax(arch[:, 0])]
    incisal = mid[(mid[:, 1] > 3.2) & (mid[:, 1] < 3.6)]
    pts["stomion"] = incisal[np.argmax(incisal[:, 2])]
    return pts


def skin_points(head_v: np.ndarray, fdp: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The skin points over the bony points of :func:`skull_points` on the ICT head (cm)."""
    mid = _midline(head_v, 0.2)
    pts = {"vertex": fdp["11.4"], "opisthocranion": fdp["11.6"], "pogonion": fdp["2.10"],
           "menton": fdp["2.1"]}
    brow = mid[(mid[:, 1] > 4.5) & (mid[:, 1] < 8.0)]
    pts["glabella"] = brow[np.argmax(brow[:, 2])]
    top = head_v[(head_v[:, 1] > 6.0) & (head_v[:, 1] < 12.0)]
    pts["euryon"] = top[np.argmax(top[:, 0])]
    face = head_v[(head_v[:, 1] > 1.5) & (head_v[:, 1] < 3.5) & (head_v[:, 2] > 1.5) & (head_v[:, 2] < 5.0)]
    pts["zygion"] = face[np.argmax(face[:, 0])]
    pts["stomion"] = (fdp["2.2"] + fdp["2.3"]) / 2.0
    return pts


#: soft-tissue depth (cm) over each bony point: Rhine 1983 via Taylor 2001 where listed
#: (glabella 4.5 mm, pogonion 13, menton 8, zygion 7); scalp at vertex, euryon and
#: opisthocranion 6 mm (not in the table; typical scalp thickness)
TISSUE_DEPTH = {"vertex": 0.6, "opisthocranion": 0.6, "glabella": 0.45, "pogonion": 1.3,
                "menton": 0.8, "euryon": 0.6, "zygion": 0.7, "stomion": 1.2}
# stomion (lips' contact line) over the upper incisal edge: lip thickness ~ 1.2 cm
# (between prosthion 11 mm and infradentale 12.25 mm of the table)


def fit_into_head(v: np.ndarray, head_v: np.ndarray, head_n: np.ndarray,
                  fdp: dict[str, np.ndarray]) -> np.ndarray:
    """Similarity params (s, a, ty, tz) mapping the source skull into the ICT head."""
    sk = skull_points(v)
    sn = skin_points(head_v, fdp)
    tree = cKDTree(head_v)
    names = sorted(TISSUE_DEPTH)
    src = np.array([sk[k] for k in names])
    dst = []
    for k in names:
        n = head_n[tree.query(sn[k])[1]]
        dst.append(sn[k] - TISSUE_DEPTH[k] * n)
    dst = np.array(dst)

    def residual(x):
        return (apply_similarity(x, src) - dst).ravel()

    x0 = np.array([1.55, 0.0, 0.0, 0.0])
    x0[2:] = (dst.mean(0) - x0[0] * src.mean(0))[1:]
    return least_squares(residual, x0).x


# ------------------------------------------------------------------------ dental warp
#: extent (template cm) of the dental warp: full drop at the occlusal line in front of
#: z = 8.5 (canines to incisors), none behind z = 4.5 (ramus, condyles); above the occlusal
#: line it fades out within 0.6 cm (the nose base, 9.15 on the bone, is 0.55 cm above the
#: incisal edge), below it within 4.2 cm (down to the chin boss, 2.10)
DENTAL_Z = (4.5, 8.5)
DENTAL_UP, DENTAL_DOWN = 0.6, 4.2


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def dental_warp(points: np.ndarray, front: np.ndarray, slope: float, drop: float) -> np.ndarray:
    """Move the dental region of the placed skull down by ``drop`` cm at the incisors: (n,3) -> (n,3).

    A similarity cannot fix the source skull's proportions: placed in the ICT head, its
    upper incisal edge sits 0.55 cm below the nasal floor and 1.6 cm above the lips'
    contact line (in real skulls the maxilla from the nasal spine to the incisal edge is
    about 2.2-2.5 cm, and the incisal edge lies at the stomion). The warp is vertical,
    ``y' = y - drop * a(z) * b(u)`` with ``u = y - y_occ(z)`` the height above the
    occlusal line ``y_occ(z) = front_y + slope * (z - front_z)`` (``front`` = (3,) incisal
    point, ``slope`` = dy/dz of the occlusal plane in the midsagittal plane):

    - ``a`` rises smoothly from 0 behind ``DENTAL_Z[0]`` to 1 in front of ``DENTAL_Z[1]``,
      so the condyles, rami and the jaw's pitch axis stay;
    - ``b`` is 1 on the occlusal line and falls to 0 at ``DENTAL_UP`` above it
      (smoothstep: the maxilla's alveolar process stretches, the nose stays) and linearly
      at ``DENTAL_DOWN`` below it (the symphysis shortens uniformly, the chin stays).

    Each vertical line maps one-to-one onto itself (``dy'/dy > 0`` whenever
    ``drop < DENTAL_DOWN``), so the bones stay closed, unfolded and apart.
    """
    p = np.asarray(points, dtype=np.float64)
    a = _smoothstep((p[:, 2] - DENTAL_Z[0]) / (DENTAL_Z[1] - DENTAL_Z[0]))
    u = p[:, 1] - (front[1] + slope * (p[:, 2] - front[2]))
    b = np.where(u >= 0.0, 1.0 - _smoothstep(u / DENTAL_UP), np.clip(1.0 + u / DENTAL_DOWN, 0.0, 1.0))
    out = p.copy()
    out[:, 1] -= drop * a * b
    return out


def incisal_point(dental_loop: np.ndarray) -> np.ndarray:
    """The front-most point (3,) of the dental cut loop near the midline (the incisal edge)."""
    front = dental_loop[np.abs(dental_loop[:, 0]) < 0.5]
    return front[np.argmax(front[:, 2])]


# ----------------------------------------------------------------------------- landmarks
def _smoothed_normals(mesh: trimesh.Trimesh, rounds: int = 3) -> np.ndarray:
    """Vertex normals averaged over the 1-ring ``rounds`` times (less noise at the lips)."""
    n = np.asarray(mesh.vertex_normals, dtype=float)
    nbrs = mesh.vertex_neighbors
    for _ in range(rounds):
        n = np.array([n[[i] + list(nb)].sum(0) for i, nb in enumerate(nbrs)])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
    return n


def place_landmark(skin_point: np.ndarray, direction: np.ndarray, bone: trimesh.Trimesh,
                   max_depth: float) -> tuple[np.ndarray, str]:
    """First hit of the ray skin_point + t*direction on ``bone`` (t <= max_depth), else closest.

    The ray starts 1 cm outside the skin so that a skin point lying (slightly) inside the
    bone still finds the bone's outer surface. Returns (point (3,), "ray" | "closest").
    """
    origin = skin_point - 1.0 * direction
    locs, _, _ = bone.ray.intersects_location(origin[None], direction[None], multiple_hits=True)
    if len(locs):
        t = (locs - origin) @ direction
        ok = (t >= 0) & (t <= max_depth + 1.0)
        if ok.any():
            return locs[ok][np.argmin(t[ok])], "ray"
    closest, _, _ = trimesh.proximity.closest_point(bone, skin_point[None])
    return closest[0], "closest"


def mirror_partners(fdp: dict[str, np.ndarray], keys) -> dict[str, str]:
    """{left FDP: right FDP} by position: the right point is the left one mirrored in x.

    (MPEG-4 numbering does not pair consecutively everywhere: 3.7 <-> 3.12, 3.8 <-> 3.11.)
    """
    keys = [k for k in keys if k in fdp]
    pairs = {}
    for k in keys:
        if fdp[k][0] <= 1e-3:
            continue
        m = fdp[k] * [-1.0, 1.0, 1.0]
        other = min((j for j in keys if fdp[j][0] < -1e-3), key=lambda j: np.linalg.norm(fdp[j] - m))
        pairs[k] = other
    return pairs


#: vertical nudge (cm) of inner-lip FDPs once the lip line is moved onto the occlusal line:
#: the inner upper lip rests on the upper incisor crowns, the inner lower lip on the lower ones
INNER_LIP_NUDGE = {"2.2": 0.3, "2.6": 0.3, "2.7": 0.3, "2.3": -0.3, "2.8": -0.3, "2.9": -0.3}


def place_landmarks(cranium, mandible, head: trimesh.Trimesh, fdp: dict[str, np.ndarray],
                    occlusal_y: float, max_depth: float = 3.0):
    """Bone landmarks {fdp: (position (3,), bone, method, skin distance)} for :data:`LANDMARK_BONES`.

    Lips and nose base (:data:`STRAIGHT_BACK`) are cast straight back (-Z). The lip FDPs are
    first moved vertically by ``occlusal_y - stomion_y`` (closed lips rest on the incisal
    edges; a similarity placement leaves the template's mouth off the skin's by up to ~1 cm),
    inner-lip ones nudged onto the crowns (:data:`INNER_LIP_NUDGE`). Midline points are cast in
    the x = 0 plane; right-side points are the mirror images of the left ones (left = +x).
    """
    bones = {"cranium": trimesh.Trimesh(*cranium, process=False),
             "mandible": trimesh.Trimesh(*mandible, process=False)}
    normals = _smoothed_normals(head)
    tree = cKDTree(np.asarray(head.vertices))
    stomion_y = (fdp["2.2"][1] + fdp["2.3"][1]) / 2.0
    partners = mirror_partners(fdp, LANDMARK_BONES)
    out = {}
    for key in sorted(LANDMARK_BONES, key=lambda k: tuple(int(p) for p in k.split("."))):
        p = fdp[key].copy()
        if p[0] < -1e-3:
            continue  # right side: mirrored below
        if key in STRAIGHT_BACK:
            d = np.array([0.0, 0.0, -1.0])
            if key.split(".")[0] in ("2", "8"):
                p[1] += occlusal_y - stomion_y + INNER_LIP_NUDGE.get(key, 0.0)
        else:
            d = -normals[tree.query(p)[1]]
        midline = abs(p[0]) <= 1e-3
        if midline:
            p[0], d[0] = 0.0, 0.0
        d = d / np.linalg.norm(d)
        bone = LANDMARK_BONES[key]
        pos, how = place_landmark(p, d, bones[bone], max_depth)
        if midline:  # keep a midline point on the midsagittal section of its bone
            pos = trimesh.proximity.closest_point(bones[bone], (pos * [0.0, 1.0, 1.0])[None])[0][0]
        out[key] = (pos, bone, how, float(np.linalg.norm(pos - fdp[key])))
        if key in partners:
            other = partners[key]
            mpos = trimesh.proximity.closest_point(bones[bone], (pos * [-1.0, 1.0, 1.0])[None])[0][0]
            out[other] = (mpos, bone, how, float(np.linalg.norm(mpos - fdp[other])))
    return out


# ------------------------------------------------------------------------------------ jaw
def jaw_axes(cut_loops: dict[str, np.ndarray]) -> dict:
    """Pitch, yaw and protrusion axes from the mandible's cut loops (template frame).

    The two condylar loops are the most posterior loop on each side; the dental loop is
    the one crossing the midline.
    """
    loops = list(cut_loops.values())
    dental = max(loops, key=len)
    left = [l for l in loops if l.mean(0)[0] > 1.0]
    right = [l for l in loops if l.mean(0)[0] < -1.0]
    cl = min(left, key=lambda l: l.mean(0)[2]).mean(0)
    cr = min(right, key=lambda l: l.mean(0)[2]).mean(0)
    # symmetric condyles: average the mirrored pair
    c = (cl + cr * [-1.0, 1.0, 1.0]) / 2.0
    cl, cr = c, c * [-1.0, 1.0, 1.0]
    centre = (cl + cr) / 2.0
    pitch_dir = (cl - cr) / np.linalg.norm(cl - cr)
    # occlusal plane normal from the dental cut; forward = its tangent in the x = 0 plane
    p = dental - dental.mean(0)
    normal = np.linalg.svd(p)[2][2]
    if normal[1] < 0:
        normal = -normal
    fwd = np.cross(pitch_dir, normal)
    fwd /= np.linalg.norm(fwd)
    if fwd[2] < 0:
        fwd = -fwd
    yaw_dir = np.cross(fwd, pitch_dir)
    yaw_dir /= np.linalg.norm(yaw_dir)
    return {"condyle_left": cl, "condyle_right": cr, "centre": centre, "pitch_dir": pitch_dir,
            "yaw_dir": yaw_dir, "protrusion_dir": fwd, "occlusal_normal": normal}


# ---------------------------------------------------------------------------------- write
def write_obj(path: Path, v: np.ndarray, f: np.ndarray, header: str) -> None:
    """Plain OBJ, 6 decimals, 1-based faces: deterministic bytes."""
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    path.write_text("\n".join(lines) + "\n")


def _r(p, nd: int = 6) -> list[float]:
    return [round(float(x), nd) + 0.0 for x in p]


def write_landmarks(path: Path, marks: dict, fdp_table: dict[str, str]) -> None:
    lines = [
        "# MPEG-4 FDP landmarks on the template skull (templates/skull/cranium.obj, mandible.obj).",
        "# Built by tools/build_template.py: each point is the first bone hit of a ray cast inward from the",
        "# FDP on the ICT-FaceKit head skin (against the smoothed skin normal; straight back (-Z) for the lips",
        "# and the nose base), on the bone named here; 'closest' marks the few points where the ray found",
        "# no bone within 3 cm (orbit, nasal aperture) and the closest bone point was taken instead.",
        "# Right-side points are mirror images (x -> -x) of the left ones. skin_depth = distance to the skin",
        "# FDP in cm (compare tissue-depth/: pogonion 1.3, glabella 0.45, supraorbital 0.85, ...).",
        "# Units: cm, +Y up, face +Z, subject's left +X, midsagittal plane x = 0.",
        "units: cm",
        f"count: {len(marks)}",
        "landmarks:",
    ]
    order = sorted(marks, key=lambda k: tuple(int(p) for p in k.split(".")))
    for k in order:
        pos, bone, how, depth = marks[k]
        lines.append(f'  "{k}": {{position: {_r(pos)}, bone: {bone}}}  '
                     f"# {fdp_table.get(k, '')} | {how}, skin_depth {depth:.2f}")
    path.write_text("\n".join(lines) + "\n")


def write_jaw(path: Path, axes: dict) -> None:
    text = f"""# Jaw axes of the template skull (section 6.1): exactly three DOFs, a rigid transform of the mandible.
# Built by tools/build_template.py. Units: cm and radians. Composition (anatomy.skull.jaw_transform):
#   first pitch about pitch_axis, then yaw about yaw_axis, then translation protrusion * protrusion.direction.
# pitch_axis: through the centres of the two condylar necks (where the mandible was cut from the temporal
#   bone), direction = subject's left; positive pitch lowers the chin (opens the mouth).
# yaw_axis: through the midpoint of the condyles, perpendicular to the occlusal plane (pointing up);
#   positive yaw turns the chin towards the subject's left (+X).
# protrusion: forward (+Z side) direction of the occlusal plane (best-fit plane of the dental cut) in the
#   midsagittal plane; positive values push the jaw forward.
units: cm
pitch_axis: {{point: {_r(axes['centre'])}, direction: {_r(axes['pitch_dir'], 6)}}}
yaw_axis: {{point: {_r(axes['centre'])}, direction: {_r(axes['yaw_dir'], 6)}}}
protrusion: {{direction: {_r(axes['protrusion_dir'], 6)}}}
condyles: {{left: {_r(axes['condyle_left'])}, right: {_r(axes['condyle_right'])}}}
limits:
  pitch: [-0.05, 0.4]        # rad; 0.4 rad parts the incisal edges by ~3.5 cm (8.9 cm from the axis)
  yaw: [-0.1, 0.1]           # rad
  protrusion: [-0.2, 0.8]    # cm; retrusion 2 mm, protrusion 8 mm
"""
    path.write_text(text)


def build(assets: Path, out: Path, dental: bool = False) -> dict:
    """Run every step; write the four files into ``out``; return a summary dict.

    ``dental``: also apply :func:`dental_warp` after the placement (experimental, off for
    the committed template; the summary's ``dental_warp`` is the map, for moving points
    such as the muscle map's, and ``dental_drop`` its drop in cm, 0 when off).
    """
    v, f = load_welded(assets / "anatomy/skull-yahoojapan/skull_low_resolution.obj")
    v[:, 0] -= mirror_plane_offset(v)
    v = symmetrise(v, f)
    placed_on = v   # the placement below is fitted on this shape (the template frame as before the mirroring)
    v, f = mirror_half(v, f)   # its own mirror image, vertex for vertex (issue 25)
    cranium, mandible, loops = split_skull(v, f)

    head = trimesh.load(assets / "heads/ict/ict_face_headneck_neutral.obj", force="mesh", process=False)
    head_v = np.asarray(head.vertices, dtype=float)
    doc = yaml.safe_load((assets / "heads/ict/ict_face_headneck_neutral.fdp.yaml").read_text())
    fdp = {k: np.asarray(d["position"], dtype=float) for k, d in doc["landmarks"].items()}
    params = fit_into_head(placed_on, head_v, np.asarray(head.vertex_normals, dtype=float), fdp)

    cranium = (apply_similarity(params, cranium[0]), cranium[1])
    mandible = (apply_similarity(params, mandible[0]), mandible[1])
    loops = {k: apply_similarity(params, l) for k, l in loops.items()}
    # optional dental registration (experimental): the incisal edge onto the lips' contact line
    fwd = jaw_axes(loops)["protrusion_dir"]
    front = incisal_point(max(loops.values(), key=len))
    drop = float(front[1] - (fdp["2.2"][1] + fdp["2.3"][1]) / 2.0) if dental else 0.0

    def warp(p):
        return dental_warp(p, front, fwd[1] / fwd[2], drop)

    if dental:
        cranium, mandible = (warp(cranium[0]), cranium[1]), (warp(mandible[0]), mandible[1])
        loops = {k: warp(l) for k, l in loops.items()}
    axes = jaw_axes(loops)
    occlusal_y = float(incisal_point(max(loops.values(), key=len))[1])
    marks = place_landmarks(cranium, mandible, head, fdp, occlusal_y)

    table = {}
    for line in (assets / "mpeg4/fdp_feature_points.csv").read_text().splitlines()[1:]:
        parts = line.split(",")
        table[parts[0]] = parts[2]
    out.mkdir(parents=True, exist_ok=True)
    src = ("derived from YahooJAPAN skull (Thingiverse 182365, remeshed by odedstein-meshes), CC BY 3.0\n"
           "built by tools/build_template.py; units cm, +Y up, face +Z, subject's left +X")
    write_obj(out / "cranium.obj", cranium[0], cranium[1], "template cranium (upper skull)\n" + src)
    write_obj(out / "mandible.obj", mandible[0], mandible[1], "template mandible\n" + src)
    write_landmarks(out / "landmarks.yaml", marks, table)
    write_jaw(out / "jaw.yaml", axes)
    return {"params": params, "cranium": cranium, "mandible": mandible, "landmarks": marks,
            "axes": axes, "dental_drop": drop, "dental_warp": warp}


#: FDP -> (tissue-depth code, Rhine 1983 depth in cm) for the build's plausibility check
DEPTH_CHECK = {"2.10": ("pg", 1.3), "2.1": ("me", 0.8), "4.1": ("g", 0.45), "4.3": ("mso", 0.85),
               "5.3": ("im", 1.2), "2.13": ("go", 1.05), "10.9": ("sgl", 0.625), "11.1": ("sg", 0.45)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--assets", type=Path, default=Path("/work/shared/assets"))
    ap.add_argument("--out", type=Path, default=ROOT / "templates" / "skull")
    ap.add_argument("--dental-warp", action="store_true",
                    help="experimental: move the dental region down onto the lips (dental_warp)")
    args = ap.parse_args(argv)
    s = build(args.assets, args.out, args.dental_warp)
    print(f"scale {s['params'][0]:.4f}, pitch {s['params'][1]:.4f} rad; cranium {len(s['cranium'][0])} v, "
          f"mandible {len(s['mandible'][0])} v, {len(s['landmarks'])} landmarks -> {args.out}")
    if args.dental_warp:
        print(f"dental warp: incisal edge moved down {s['dental_drop']:.2f} cm onto the lips' contact line")
    print("skin-to-bone distance at the landmarks vs. the soft-tissue depth table (cm):")
    for k, (code, depth) in DEPTH_CHECK.items():
        print(f"  {k:>5} {code:>4}: template {s['landmarks'][k][3]:.2f}, table {depth:.2f}")


if __name__ == "__main__":
    main()
