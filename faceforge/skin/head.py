"""The whole §8 binding of one head: cut the lips, bind the skin by rays and the rules beyond
the paper, the influence map (Fig. 9) and the report (:func:`bind_head`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import check_mesh, smooth_vertex_normals
from faceforge.skin.binding import CRANIUM, MANDIBLE, MUSCLE, Binding, Body, BrowRegion, InsertionRegions, bind_skin
from faceforge.skin.mouth import AROUND_MOUTH
from faceforge.skin.regions import bind_report, face_front_mask
from faceforge.skin.brow import BROW_BAND_MM, brow_mask, eye_mask
from faceforge.skin.rules import (COMMISSURE_RADIUS, MODIOLUS_RADIUS, lip_band, lip_band_width, match_insertions,
                                  modiolus_mask, commissure_mask, nose_mask, vermilion_mask)


@dataclass(frozen=True)
class BoundSkin:
    """Everything :func:`bind_head` finds (the content of the bind stage).

    Attributes
    ----------
    cut : faceforge.skin.mouth.MouthCut
        The working skin mesh (``cut.vertices``, ``cut.faces``) and the mapping
        back to the user's vertices.
    binding : Binding
        Anchors over the working vertices.
    lip_sides : (n,) int8
        +1 upper lip, -1 lower lip, 0 elsewhere (working vertices).
    weights : (n,) float64
        Influence map in [0, 1] (working vertices).
    geodesic : (n,) float64
        Geodesic distance from the anchored region.
    scale : float
        The influence normalisation (distance to the back of the head).
    front : (n,) bool
        The face-front region (in front of the ears, below the hairline).
    report : dict
        The bind report (JSON-ready).
    parts : (n,) int8 or None
        The pieces that ride a bone rigidly (:func:`faceforge.skin.parts.rigid_parts`: eyeballs,
        teeth; 0 = skin), None without bones.
    """

    cut: object
    binding: Binding
    lip_sides: np.ndarray
    weights: np.ndarray
    geodesic: np.ndarray
    scale: float
    front: np.ndarray
    report: dict
    parts: np.ndarray | None = None

    def as_arrays(self) -> dict:
        """Flat arrays for ``bind.npz`` (no pickle). Anchor arrays are prefixed ``anchor_``."""
        c = self.cut
        out = {
            "n_user": np.int64(c.n_user), "vertices": c.vertices, "faces": c.faces,
            "duplicate_source": c.source, "removed_faces": c.removed_faces,
            "lip_upper": c.upper, "lip_lower": c.lower, "lip_sides": self.lip_sides,
            "influence": self.weights, "geodesic": self.geodesic,
            "influence_scale": np.float64(self.scale), "front": self.front,
        }
        if self.parts is not None:
            out["parts"] = self.parts
        for key, value in self.binding.as_arrays().items():
            out[key if key in ("status", "normals", "body_names") else f"anchor_{key}"] = value
        return out


def _nearest_vertex(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    from scipy.spatial import cKDTree

    return cKDTree(vertices).query(points)[1].astype(INT)


def bind_head(vertices, faces, landmarks: dict, cranium, mandible, muscles,
              max_ray_fraction: float, up=(0.0, 1.0, 0.0), insertions=(), lips_to_ring=True,
              modiolus_radius: float = MODIOLUS_RADIUS, mirror=None, brow_band_mm: float = BROW_BAND_MM,
              brow_muscles=(), brow_shared_mm: float = 0.0, brow_raisers=(), cheek_mm: float = 0.0,
              forehead_bone_mm: float = 0.0,
              cheek_muscles=(), commissure_radius: float = COMMISSURE_RADIUS,
              vermilion: float = 0.0, nose_on_bone: bool = False, normal_rounds: int = 0,
              ala_mm: float = 0.0, ala_muscles=(), vermilion_depth_mm: float = 0.0) -> BoundSkin:
    """Cut the lips, bind the skin (§8) and compute the influence map (Fig. 9).

    Parameters
    ----------
    vertices : (n, 3) float
        The user's skin (triangulated), skin units.
    faces : (m, 3) int
    landmarks : dict
        FDP id -> (3,) position on the skin.
    cranium, mandible : tuple (vertices (k, 3), faces (l, 3)) or None
        The fitted skull parts (skin units).
    muscles : sequence of tuple (name, layer, vertices, faces)
        The fitted muscles' rest meshes; a higher layer is more superficial
        (tested first); within one layer the nearest hit wins.
    max_ray_fraction : float
        ``bind.max_ray_distance``: longest ray as a fraction of the skin's
        bounding-box diagonal.
    insertions : sequence of str
        ``bind.insertions``: muscles that insert into the skin through the muscles above
        them, by name or by the name of a left/right pair without ``_L`` / ``_R``; skin
        bound to another muscle gets a second anchor on them (:func:`bind_skin`).
    lips_to_ring : bool
        ``bind.lips_to_ring``: lip skin whose rays miss binds to its own arc of the orbicularis
        oris before the teeth (:func:`bind_skin`).
    modiolus_radius : float
        ``bind.modiolus_radius``: the skin within this fraction of MW0 of a mouth corner
        binds to the orbicularis oris (:func:`modiolus_mask`; 0: by its rays, as the paper).
    commissure_radius : float
        ``bind.commissure_radius``: the lip skin within this fraction of MW0 of an inner lip
        corner on the orbicularis oris binds to either lip's arc of it (:func:`commissure_mask`,
        :func:`faceforge.skin.bind_passes.commissure_anchors`; 0: its own lip's arc only).
    normal_rounds : int
        ``bind.normal_rounds``: the rays are cast along the skin's normals averaged over neighbours
        that many times (:func:`faceforge.geometry.triangles.smooth_vertex_normals`; 0: the
        area-weighted vertex normals), so a scan's noise does not scatter the anchors.
    vermilion : float
        ``bind.vermilion_reach``: the lip skin within this many midline heights of its inner lip
        contour (:func:`vermilion_mask`; 1: the red of the lips), out of the modiolus mask (the
        corners keep their rule), that its rays bound to the skull binds to its own lip's arc of
        the orbicularis oris
        (:func:`faceforge.skin.bind_passes.vermilion_anchors`; 0: by its rays).
    vermilion_depth_mm : float
        ``bind.vermilion_depth_mm``: the red of the lips (:func:`vermilion_mask` at 1, out of the
        modiolus mask) that its rays bound deeper than this many mm (scaled by ES0) to a muscle
        not around the mouth binds to its own lip's arc of the orbicularis oris
        (:func:`faceforge.skin.bind_passes.deep_vermilion_anchors`; 0: by its rays).
    brow_band_mm, brow_muscles : float, sequence of str
        ``bind.brow_band_mm``, ``bind.brow_muscles`` (names or pair names as ``insertions``):
        brow skin that its rays bound to the bone binds to the closest brow muscle
        (:mod:`faceforge.skin.brow`; 0 or none: by its rays, as the paper).
    brow_shared_mm : float
        ``bind.brow_shared_mm``: brow skin on one brow muscle also anchors to the nearest other
        insertion within this many mm (scaled by ES0) of its anchor
        (:func:`faceforge.skin.brow.shared_anchors`; 0: off).
    brow_raisers : sequence of str
        ``bind.brow_raisers`` (names or pair names): brow skin on another muscle also anchors
        to the nearest of these within ``brow_shared_mm`` (:func:`faceforge.skin.brow.raiser_anchors`).
    forehead_bone_mm : float
        ``bind.forehead_bone_mm``: forehead skin farther than this many mm (scaled by ES0) above
        the brow lines whose anchors are all on ``brow_raisers`` binds to the closest point of
        the cranium instead (:func:`faceforge.skin.brow.onto_cranium`; 0: off).
    cheek_mm, cheek_muscles : float, sequence of str
        ``bind.cheek_mm``, ``bind.cheek_muscles``: cheek skin within this many mm of FDP 5.3 /
        5.4 that its rays bound to the bone binds to the closest cheek muscle
        (:mod:`faceforge.skin.cheek`; 0 or none: by its rays, as the paper).
    nose_on_bone : bool
        ``bind.nose_on_bone``: the nose's skin (:func:`nose_mask`: at or above the nose base 9.15,
        within the alae, the nostrils' insides) whose anchors are all on the muscles around the
        mouth binds to the closest point of the cranium instead (the nasal cartilages; the
        rebinding of :func:`faceforge.skin.brow.onto_cranium`). The ring's upper rows (its
        pars peripheralis, at the nasal sill) lie behind the nostrils and the columella, and by
        their rays these bound to it: a pucker or a rounded viseme, which lifts and pushes the
        ring, carried the nose with the lip (docs/notes/tent17.md). False: by the rays.
    ala_mm, ala_muscles : float, sequence of str
        ``bind.ala_mm``, ``bind.ala_muscles``: the ala's skin (:func:`faceforge.skin.ala.ala_mask`:
        within this many mm of the alar base-to-crease line) that its rays (or ``nose_on_bone``)
        bound to the bone binds to these muscles instead (the levator labii superioris alaeque
        nasi, whose medial slip inserts into the alar cartilage and its skin), at the point of
        their part beside the ala nearest the ala's own height
        (:func:`faceforge.skin.ala.ala_binding`); 0 or none: off.
    mirror : faceforge.geometry.mirror.Mirror or None
        A symmetric rig's plane (fit.npz): each right skin vertex is bound as the mirror
        image of its left partner (:func:`faceforge.skin.mirror.mirror_binding`).

    Inner lips (:func:`lip_band`, :data:`LIP_BAND_MM`): like all the face's front skin,
    inner lip skin whose rays miss gets a closest-point anchor, across the oral vestibule
    (1.4 cm on ICT): the upper lip on the maxilla, the lower on the mandible
    (``lip_sides``), so every front vertex is bound. The lip corners' small triangles
    between those and the orbicularis oris used to turn over while the jaw moved, which is
    why this band was once left unbound; the skin's orientation guard
    (:mod:`faceforge.animation.guards.orientation`) now keeps them upright. The band is still
    a region of the report.

    Returns
    -------
    BoundSkin

    Length (107 lines, half of it docstring and report): the §8 steps in order; left as it is
    (issue 24).
    """
    from faceforge.skin.influence import influence_weights
    from faceforge.skin.mouth import (LIP_FDPS, cut_mouth, lip_side, muscle_lip_side,
                                         ring_face_sides, side_of_points)

    v, f = check_mesh(vertices, faces)
    pts = {k: np.asarray(p, FLOAT) for k, p in landmarks.items()}
    lips = [k for k in LIP_FDPS if k in pts]
    lip_ids = dict(zip(lips, _nearest_vertex(v, np.array([pts[k] for k in lips])))) if lips else {}
    cut = cut_mouth(v, f, lip_ids, up=up)
    sides = lip_side(cut, up=up)

    def side_of(points):
        return side_of_points(points, cut, up=up)


    order = sorted(range(len(muscles)), key=lambda i: -int(muscles[i][1]))  # stable
    bodies = [Body(str(muscles[i][0]), "muscle", muscles[i][2], muscles[i][3]) for i in order]
    rank = [-int(muscles[i][1]) for i in order]
    if cranium is not None:
        bodies.append(Body("cranium", "cranium", *cranium))
        rank.append(0)
    if mandible is not None:
        bodies.append(Body("mandible", "mandible", *mandible))
        rank.append(0)
    diagonal = float(np.linalg.norm(np.ptp(v, axis=0)))
    front, rule = face_front_mask(cut.vertices, pts)
    band_width = lip_band_width(pts)
    lips = lip_band(cut, band_width)
    ins, _ = match_insertions(insertions, [b.name if b.kind == "muscle" else None for b in bodies])
    corner = modiolus_mask(cut.vertices, pts, modiolus_radius)
    commissure = commissure_mask(cut.vertices, pts, commissure_radius)
    verm = vermilion_mask(cut, sides, pts, vermilion) & ~corner if vermilion > 0 else None   # the corners: the modiolus'
    deep = vermilion_mask(cut, sides, pts, 1.0) & ~corner if vermilion_depth_mm > 0 else None
    brow_ids, _ = match_insertions(brow_muscles, [b.name if b.kind == "muscle" else None for b in bodies])
    brow = brow_mask(cut.vertices, pts, brow_band_mm, up=up) if brow_ids else np.zeros(len(cut.vertices), bool)
    eye_ids, _ = match_insertions(tuple(brow_muscles) + ("orbicularis_oculi",) if brow_ids else (),
                                  [b.name if b.kind == "muscle" else None for b in bodies])
    eye = eye_mask(cut.vertices, pts, up=up) if eye_ids else np.zeros(len(cut.vertices), bool)
    from faceforge.anatomy.tissue import units_per_mm

    shared = brow_shared_mm * units_per_mm(pts) if brow.any() and brow_shared_mm > 0 else 0.0
    raiser_ids, _ = match_insertions(brow_raisers, [b.name if b.kind == "muscle" else None for b in bodies])
    body_sides = [muscle_lip_side(b.vertices[np.unique(b.faces)], cut, up=up) if b.kind == "muscle" else 0
                  for b in bodies]
    face_sides = [ring_face_sides(b.vertices, b.faces, cut, up=up) if s == AROUND_MOUTH else None
                  for b, s in zip(bodies, body_sides)]
    normals = smooth_vertex_normals(cut.vertices, cut.faces, normal_rounds) if normal_rounds > 0 else None
    binding = bind_skin(cut.vertices, cut.faces, bodies, max_ray_fraction * diagonal, lip_sides=sides, normals=normals,
                        depth_rank=rank, side_of=side_of, fallback=front, body_sides=body_sides,
                        insertions=ins, face_sides=face_sides, lips_to_ring=lips_to_ring,
                        regions=InsertionRegions(modiolus=corner, commissure=commissure, vermilion=verm,
                                                 deep=deep, deep_depth=vermilion_depth_mm * units_per_mm(pts)
                                                 if deep is not None else 0.0,
                                                 brow=BrowRegion(brow, tuple(brow_ids), ((eye, eye_ids),),
                                                                 shared, tuple(raiser_ids))))
    cheek_ids, _ = match_insertions(cheek_muscles, [b.name if b.kind == "muscle" else None for b in bodies])
    if cheek_ids and cheek_mm > 0:   # the cheek's insertion: cheek skin on the bone moves to the cheek raiser
        from faceforge.skin.cheek import cheek_binding, cheek_mask

        binding, _ = cheek_binding(binding, cut.vertices, bodies, cheek_ids, cheek_mask(cut.vertices, pts, cheek_mm, up),
                                   max_ray_fraction * diagonal)
    forehead = 0
    if forehead_bone_mm > 0 and raiser_ids:   # the forehead above the brow: on the galea and bone, not the frontalis
        from faceforge.skin.brow import forehead_mask, onto_cranium

        binding, forehead = onto_cranium(binding, cut.vertices, bodies, raiser_ids,
                                         forehead_mask(cut.vertices, pts, forehead_bone_mm, up=up),
                                         max_ray_fraction * diagonal)
    nose = 0
    if nose_on_bone:   # the nose on its cartilages, off the ring behind the nostrils
        from faceforge.skin.brow import onto_cranium

        ring = [i for i, s in enumerate(body_sides) if s == AROUND_MOUTH]
        binding, nose = onto_cranium(binding, cut.vertices, bodies, ring, nose_mask(cut.vertices, pts, up),
                                     max_ray_fraction * diagonal)
    ala = 0
    ala_ids, _ = match_insertions(ala_muscles, [b.name if b.kind == "muscle" else None for b in bodies])
    if ala_ids and ala_mm > 0:   # the ala on the levator labii alaeque nasi's medial slip, off the bone
        from faceforge.skin.ala import ala_binding, ala_mask

        binding, ala = ala_binding(binding, cut.vertices, bodies, ala_ids, ala_mask(cut.vertices, pts, ala_mm),
                                   max_ray_fraction * diagonal, up=up, landmarks=pts)
    mirrored = 0
    if mirror is not None:
        from faceforge.skin.mirror import MIRROR_TOLERANCE, mirror_binding

        binding, mirrored = mirror_binding(binding, cut.vertices, bodies, mirror, MIRROR_TOLERANCE * diagonal)

    sources = np.flatnonzero(np.isin(binding.status, (MUSCLE, MANDIBLE)))
    back = int(_nearest_vertex(cut.vertices, pts["11.6"][None])[0]) if "11.6" in pts else None
    weights, dist, scale = influence_weights(cut.vertices, cut.faces, sources, back_vertex=back)

    report = bind_report(binding, {"face_front": front, "face_front_outside_lips": front & ~lips,
                                   "lip_band": lips, "back_and_neck": ~front})
    report["region_rules"] = rule
    report["mirrored_vertices"] = mirrored
    if forehead_bone_mm > 0:   # (off, the report as before: a workdir's calibration stays current)
        report["forehead_on_bone"] = forehead
    if nose_on_bone:   # (off, the report as before)
        report["nose_on_bone"] = nose
    if ala_ids and ala_mm > 0:   # (named only when on: the report as before with bind.ala_mm 0)
        report["ala_on_muscle"] = ala
    report["max_ray_distance"] = max_ray_fraction * diagonal
    report["lip_band_width"] = band_width
    kind = binding.status[corner]   # the kind of each corner vertex's (first) anchor
    first = np.r_[True, binding.vertex_ids[1:] != binding.vertex_ids[:-1]]
    on_ring = int((np.isin(binding.vertex_ids[first], np.flatnonzero(corner)) & np.isin(
        binding.body[first], [i for i, s in enumerate(body_sides) if s == AROUND_MOUTH])).sum())
    report["modiolus"] = {"radius_mw0": float(modiolus_radius), "vertices": int(corner.sum()),
                          "on_the_ring": on_ring,
                          "on_bone": int(np.isin(kind, (CRANIUM, MANDIBLE)).sum()),
                          "on_other_muscles": int((kind == MUSCLE).sum()) - on_ring}
    first_of = binding.vertex_ids[first]
    report["brow"] = {"band_mm": float(brow_band_mm), "vertices": int(brow.sum()),
                      "on_brow_muscles": int((np.isin(first_of, np.flatnonzero(brow))
                                              & np.isin(binding.body[first], brow_ids)).sum())}
    report["eyes"] = {"vertices": int(eye.sum()),
                      "on_brow_muscles": int((np.isin(first_of, np.flatnonzero(eye))
                                              & np.isin(binding.body[first], eye_ids)).sum())}
    report["mouth"] = cut.report()
    parts = None
    if cranium is not None and mandible is not None and pts:
        from faceforge.skin.parts import part_counts, rigid_parts

        marks = _nearest_vertex(cut.vertices, np.array(list(pts.values())))
        mouth = 0.5 * (pts["2.2"] + pts["2.3"]) @ np.asarray(up, FLOAT) / np.linalg.norm(up) \
            if "2.2" in pts and "2.3" in pts else None
        parts = rigid_parts(cut.vertices, cut.faces, marks, cranium, mandible, mouth, up)
        report["rigid_parts"] = part_counts(parts)
    report["influence"] = {
        "sources": int(len(sources)), "normalisation": float(scale),
        "normalised_by": "geodesic distance to FDP 11.6" if back is not None else "largest distance",
        "mean_weight": float(weights.mean()) if len(weights) else 0.0,
    }
    return BoundSkin(cut, binding, sides, weights, dist, float(scale), front, report, parts)
