"""A symmetric rig for a symmetric head (issue 25): the fitted skull, muscles and jaw made
mirror-symmetric, and the rig built symmetric by construction.

The template skull was a real skull, symmetric only to its mesh (its triangulation was not a
mirror image of itself), and the fit's enhancement landmarks are chosen vertex by vertex, so
even an exactly symmetric skin (MakeHuman) got a lopsided rig: left and right units differed by
18-78 % of their motion. When every vertex of the skin has a mirror partner about the plane its
left/right landmark pairs span (:func:`skin_asymmetry`, the worst vertex, below
``fit.symmetric_tolerance`` x ES0):

* :func:`symmetrize_bones` (before the eye sockets and the clearance) averages each fitted
  bone vertex with its partner's mirror image (the template skull is its own mirror image
  vertex for vertex, :func:`bone_partners`; once more after the eye sockets and the
  clearance, which are fitted per side), so the fitted bone is exactly symmetric; a template
  without partners moves halfway to its mirror image instead (closest points, smoothed). Each
  right muscle is averaged with its mirrored left twin; the midline point sets move halfway
  to their mirror images;
* :func:`symmetrize_fit` does the same to the muscle map and puts the jaw's axes on the plane,
  and stores the plane (``FitResult.mirror``, fit.npz ``mirror_point`` / ``mirror_normal``);
* :func:`rebuild_muscles` rebuilds the muscles as the animate stage builds them with the plane
  (:func:`faceforge.anatomy.muscles.build.build_muscles_on`): each right muscle the mirror image
  of its left twin, the orbicularis oris' right half that of its left half
  (:mod:`faceforge.anatomy.muscles.mirror`); bind then binds each right skin vertex as the
  mirror image of its partner (:mod:`faceforge.skin.mirror`).

Everything is in head space (mesh units). No template file changes: an asymmetric head (a
scan) keeps the fit as it is.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from faceforge.geometry.mirror import Mirror

__all__ = ["Mirror", "bone_partners", "exact_plane", "mirror_plane", "pairs_halfway", "skin_asymmetry",
           "symmetrize_bones", "symmetrize_fit"]

#: left/right FDP pairs that span the midsagittal plane (ISO/IEC 14496-2 Annex C)
FDP_PAIRS = (("3.5", "3.6"), ("3.7", "3.12"), ("3.11", "3.8"), ("4.1", "4.2"), ("4.3", "4.4"),
             ("4.5", "4.6"), ("8.3", "8.4"), ("2.4", "2.5"), ("9.1", "9.2"), ("9.5", "9.4"),
             ("5.1", "5.2"), ("5.3", "5.4"), ("2.13", "2.14"), ("10.9", "10.10"), ("8.5", "8.6"),
             ("8.7", "8.8"), ("2.6", "2.7"), ("2.8", "2.9"))


def mirror_plane(landmarks: dict) -> tuple[Mirror, float] | None:
    """The head's midsagittal plane from its left/right FDP pairs, and ES0 (pupils, else outer
    eye corners; mesh units). ``landmarks`` {fdp: (3,)}; None with fewer than three pairs."""
    pairs = [(np.asarray(landmarks[a], float), np.asarray(landmarks[b], float))
             for a, b in FDP_PAIRS if a in landmarks and b in landmarks]
    if len(pairs) < 3:
        return None
    left, right = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    normal = (left - right).sum(axis=0)
    mirror = Mirror(0.5 * (left + right).mean(axis=0), normal)
    eyes = ("3.5", "3.6") if "3.5" in landmarks and "3.6" in landmarks else ("3.7", "3.12")
    es0 = float(np.linalg.norm(np.asarray(landmarks[eyes[0]], float) - landmarks[eyes[1]])) \
        if eyes[0] in landmarks and eyes[1] in landmarks else float(np.linalg.norm(left - right, axis=1).mean())
    return mirror, es0


def exact_plane(vertices: np.ndarray, mirror: Mirror, rounds: int = 3) -> Mirror | None:
    """The plane about which ``vertices (n, 3)`` are their own mirror image exactly
    (:meth:`Mirror.exact_partners`), found from ``mirror`` (the landmarks' plane) by matching each
    vertex with the vertex nearest its mirror image and putting the plane through the pairs'
    midpoints, normal along their differences (``rounds`` times); None when the vertices are not
    exactly symmetric about it.

    The landmarks' plane misses a symmetric skin when its points were snapped onto a surface whose
    triangulation is not symmetric (quads split along either diagonal): the skin then counted as
    symmetric within ``fit.symmetric_tolerance`` but no vertex found its exact partner, and the rig
    was built lopsided (every right entry calibrated on its own)."""
    v = np.asarray(vertices, dtype=np.float64)
    for _ in range(rounds):
        if mirror.exact_partners(v) is not None:
            return mirror
        j, _ = mirror.partners(v)
        apart = v - v[j]
        off = np.linalg.norm(apart, axis=1) > 0.0            # pairs of two vertices (not on the plane)
        if off.sum() < 3:
            return None
        d = apart[off] * np.sign(apart[off] @ mirror.normal)[:, None]
        mirror = Mirror(0.5 * (v[off] + v[j[off]]).mean(axis=0), d.mean(axis=0))
    return mirror if mirror.exact_partners(v) is not None else None


def skin_asymmetry(vertices: np.ndarray, mirror: Mirror) -> float:
    """Largest distance (mesh units) from a mirrored vertex (n, 3) to the nearest vertex: 0 when
    every vertex has a mirror partner."""
    return float(mirror.partners(vertices)[1].max())


def _points_halfway(p: np.ndarray, mirror: Mirror, rounds: int = 2) -> np.ndarray:
    """Each point (k, 3) moved halfway to the nearest point of the mirrored set, ``rounds`` times."""
    from scipy.spatial import cKDTree

    p = np.asarray(p, dtype=np.float64)
    for _ in range(rounds):
        m = mirror(p)
        j = cKDTree(m).query(p)[1]
        p = 0.5 * (p + m[j])
    return p


def _surface_halfway(v: np.ndarray, f: np.ndarray, mirror: Mirror, rounds: int = 6,
                     smooth: int = 4) -> np.ndarray:
    """Each vertex (n, 3) of the mesh (v, f) moved halfway to the closest point of the mirrored
    surface, ``rounds`` times (the mirrored surface taken afresh each time), the move smoothed
    by ``smooth`` sweeps of the neighbours' average."""
    from faceforge.geometry.closest import TriangleGrid
    from faceforge.geometry.triangles import neighbour_average

    v = np.asarray(v, dtype=np.float64)
    f = np.asarray(f)
    # the move is smoothed over the mesh (a few Jacobi sweeps of the umbrella average), so a
    # thin plate whose two sides find different partners is not folded through itself
    avg = neighbour_average(len(v), f)
    for _ in range(rounds):
        q, _ = TriangleGrid(mirror(v)[f]).closest(v)
        move = 0.5 * (q - v)
        for _ in range(smooth):
            move = 0.5 * (move + avg @ move)
        v = v + move
    return v


def point_partners(named: dict, tol: float = 0.05) -> dict:
    """{name: (k,) partner index} for the point sets (k, 3) of ``named`` (template space, plane
    x = 0) that are their own mirror images: each point's mirror partner, when the pairing is
    one to one within ``tol`` (template units). A fitted midline muscle's points are paired
    by it (:func:`_twins`); paired afresh in head space, two points near the plane can take
    the same partner (MakeHuman's mentalis origin: 0 and 0.013 units from the plane, its
    template points 1.6 cm apart)."""
    from scipy.spatial import cKDTree

    out = {}
    for name, p in named.items():
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        if len(p) < 2 or name.endswith(("_L", "_R")):
            continue
        d, j = cKDTree(p).query(p * [-1.0, 1.0, 1.0])
        if float(d.max()) <= tol and len(np.unique(j)) == len(p):
            out[name] = j
    return out


def _twins(named: dict, mirror: Mirror, partners: dict | None = None) -> dict:
    """{name: (k, 3)} with ``*_L`` / ``*_R`` twins of equal shape averaged through the mirror
    (right = mirror of left, point by point), a set in ``partners`` ({name: (k,)},
    :func:`point_partners`) averaged with its partners' mirror images, the rest moved halfway
    to their mirror images."""
    out = {}
    partners = partners or {}
    for name, p in named.items():
        p = np.asarray(p, dtype=np.float64)
        if name.endswith("_L") and name[:-2] + "_R" in named and np.shape(named[name[:-2] + "_R"]) == p.shape:
            left = 0.5 * (p + mirror(named[name[:-2] + "_R"]))
            out[name], out[name[:-2] + "_R"] = left, mirror(left)
        elif name.endswith("_R") and name[:-2] + "_L" in named and np.shape(named[name[:-2] + "_L"]) == p.shape:
            continue
        elif name in partners and len(partners[name]) == len(p):
            out[name] = 0.5 * (p + mirror(p[partners[name]]))
        else:
            out[name] = _points_halfway(p, mirror) if len(p) > 1 else p
    return out


def _axis(point, direction, mirror: Mirror, across: bool):
    """A jaw axis made symmetric: the point onto the plane; the direction across the plane
    (``across``: the pitch axis) or into it."""
    p = np.asarray(point, dtype=np.float64)
    p = p - ((p - mirror.point) @ mirror.normal) * mirror.normal
    d = np.asarray(direction, dtype=np.float64)
    d = 0.5 * (d - mirror.direction(d)) if across else 0.5 * (d + mirror.direction(d))
    return p, d / np.linalg.norm(d)


def bone_partners(cranium: np.ndarray, mandible: np.ndarray) -> np.ndarray | None:
    """Each template bone vertex's mirror partner (n_cranium + n_mandible,), indices into the
    stacked bones, when both bones are their own mirror images about x = 0 vertex for vertex
    (the template since issue 25, :func:`faceforge.geometry.mirror_mesh.mirror_half`); else None."""
    from faceforge.geometry.mirror_mesh import vertex_partners

    pc, pm = vertex_partners(cranium), vertex_partners(mandible)
    return None if pc is None or pm is None else np.concatenate([pc, pm + len(cranium)])


def pairs_halfway(v: np.ndarray, partners: np.ndarray, mirror: Mirror) -> np.ndarray:
    """Each vertex (n, 3) averaged with its partner's mirror image (``partners`` (n,)): the
    result is exactly symmetric about ``mirror`` and moves a symmetric fit by nothing."""
    v = np.asarray(v, dtype=np.float64)
    return 0.5 * (v + mirror(v[partners]))


def symmetrize_bones(skull: np.ndarray, n_cranium: int, cranium_faces, mandible_faces, muscles,
                     mirror: Mirror, partners: np.ndarray | None = None) -> tuple[np.ndarray, list]:
    """The fitted skull ``(n, 3)`` (cranium rows first, ``n_cranium`` of them) and muscles
    ``[(name, vertices, faces)]`` made mirror-symmetric (module docstring); new arrays.
    ``partners`` (n,) (:func:`bone_partners`): the bone's vertex pairs are averaged exactly;
    without (a template whose triangulation is not its own mirror image) each vertex moves
    halfway to the mirrored surface. :func:`faceforge.fit.head.fit_head` calls it before the
    bone is cleared off the skin."""
    if partners is not None:
        bone = pairs_halfway(skull, partners, mirror)
    else:
        bone = np.vstack([_surface_halfway(skull[:n_cranium], cranium_faces, mirror),
                          _surface_halfway(skull[n_cranium:], mandible_faces, mirror)])
    built = _twins({n: v for n, v, _ in muscles}, mirror)
    faces = {n: f for n, _, f in muscles}
    for n in faces:   # a right twin's faces: the left's, turned (a reflection turns the surface inside out)
        if n.endswith("_R") and n[:-2] + "_L" in faces and np.shape(faces[n]) == np.shape(faces[n[:-2] + "_L"]):
            faces[n] = np.ascontiguousarray(np.asarray(faces[n[:-2] + "_L"])[:, ::-1])
    return bone, [(n, built[n], faces[n]) for n, _, _ in muscles]


def symmetrize_fit(result, mirror: Mirror, partners: dict | None = None):
    """The :class:`faceforge.fit.head.FitResult` ``result``'s muscle map and jaw axes made
    mirror-symmetric about ``mirror`` (its bones and muscles: :func:`symmetrize_bones`); a
    midline muscle's points paired by ``partners`` (:func:`point_partners` of the template's
    muscle map). A new FitResult, ``result`` is not changed."""
    jaw = {name: _axis(p, d, mirror, across=(name == "pitch")) for name, (p, d) in result.jaw_axes.items()}
    info = dict(result.info, symmetric=True)
    return replace(result, jaw_axes=jaw, muscle_points=_twins(result.muscle_points, mirror, partners),
                   info=info, mirror=mirror)


def rebuild_muscles(result, specs):
    """The FitResult ``result`` of a symmetric rig with its muscles rebuilt as the animate stage
    builds them (:func:`faceforge.anatomy.muscles.build.build_muscles_on` on the fitted bone
    from the fitted muscle map, each right muscle the mirror image of its left twin, the
    orbicularis oris' right half that of its left half): bind then binds the skin to the very
    faces the rig moves, and a right skin vertex can be bound as the mirror image of its
    partner (:func:`faceforge.skin.mirror.mirror_binding`). ``specs``: the template's
    [MuscleSpec]. A map whose muscles cannot be built on this bone keeps the morphed ones."""
    from faceforge.anatomy.muscles.build import build_muscles_on
    from faceforge.exceptions import TemplateError

    cranium = (result.cranium, result.cranium_faces)
    mandible = (result.mandible, result.mandible_faces)
    diagonal = float(np.linalg.norm(np.ptp(np.vstack([result.cranium, result.mandible]), axis=0)))
    fitted = [s.with_points(result.muscle_points[s.name]) for s in specs if s.name in result.muscle_points]
    try:
        built = {m.name: m for m in build_muscles_on(fitted, cranium, mandible, diagonal, mirror=result.mirror)}
    except TemplateError:
        return result
    muscles = [(n, built[n].rest_positions, built[n].faces) if n in built else (n, v, f) for n, v, f in result.muscles]
    return replace(result, muscles=muscles, info=dict(result.info, muscles_rebuilt=True))
