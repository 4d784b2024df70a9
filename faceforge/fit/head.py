"""Fit the template skull and muscle map into a skin mesh (§7, Fig. 8).

Functions on arrays. The construction, in order:

1. **Targets.** For each FDP present on both the skull template and the skin, the skin
   landmark is moved inward along the skin normal by the published soft-tissue depth
   beneath it (:mod:`faceforge.anatomy.tissue`, scaled by ES0). FDPs without bone
   beneath them (nose tip, inner lips, pupils, ears) are not skull targets.
2. **Initial alignment.** A similarity transform (scale, rotation, translation; Umeyama
   1991 least squares) takes the skull landmarks onto the targets, so heads in any unit
   and a moderately rotated pose fit.
3. **Hardy multiquadric RBF** (§4, :func:`faceforge.geometry.rbf.hardy_rbf`) from the
   aligned skull landmarks to the targets; exact at the landmarks.
4. **Enhancement landmarks** (red dots of Fig. 8). Candidate points are the outer-surface
   vertices (one per ``enhancement_cell`` grid cell) of the morphed skull in front of the
   ears (a vertex is *outer* when a ray along its normal leaves the skull without hitting
   it again) that face the skin (their normal within ~70 degrees of the skin normal at
   their closest skin point: this leaves out the back of the teeth and the inside of the
   jaw). The signed depth ``D`` beneath
   the closest skin point (:func:`signed_skin_depth`; negative when the bone pokes
   through) is compared with the expected depth ``t*`` (Shepard interpolation of the
   landmark depths); where ``D < enhancement_min_ratio * t*`` the vertex is *bad*.
   Up to ``enhancement_samples`` bad vertices are taken, worst first, each at least
   ``enhancement_spacing`` apart from the others and from every existing source; each
   pair (skull point -> closest skin point - ``t*`` along the skin normal) is a ray from
   the skin inward to the bone (the red dots of Fig. 8); ``enhancement_rounds`` rounds or
   until nothing is bad. With ``enhancement_flow_steps`` > 0 (the default, 8) each round's pairs are met by a
   *flow* (:func:`enhancement_field`, :class:`Flow`): a smooth displacement field, zero at
   every earlier pair's target (the FDP landmarks lie on theirs, exactly) and the correction
   at each new pair, integrated in that many midpoint steps. A flow is one-to-one in the
   continuum, so it does not turn the bone over the way the exact RBF through a close-spaced
   enhancement pair and an FDP landmark does (only triangles larger than the field's
   detail still can): on MakeHuman the whole fit turns over 250 cranium and 64 mandible
   triangles with the exact RBF, 140 and 10 with the flow (of which 40 and 0 already come
   from the FDP RBF). A flow moves each new pair most of the way to its target (~70 %), not
   onto it, and stops short of a landmark in its way; enhancement targets are a depth
   ratio, and the next round tests again. With 0 the RBF through all pairs is rebuilt each
   round with the landmarks' shape parameter (the paper's construction; it can also run
   away: with a template whose teeth sit at the lips, one round moved the inside of
   MediaPipe's orbit by 40 % of the skin diagonal).
   Points in pockets (teeth in a modelled mouth) and points no skin covers (beyond a
   mask's rim, below the neck) are left alone: the back need not fit (§7). The other way
   round, skin of the face that the bone swallows (a deep modelled eye socket, a nostril
   reaching into the nasal aperture) adds pairs that push the nearest bone vertex along
   its normal until the skin is ``skin_clearance_mm`` outside
   (:func:`skin_inside_bone_pairs`). Template
   landmarks the skin cannot place and that lie far from every target (a face mask has
   no skull top, back or jaw angles) are *anchors*: held where the similarity puts them,
   so the RBF does not extrapolate the back of the skull.
5. **Muscles** (:mod:`faceforge.fit.muscles`): the muscles (built on the template
   skull) are morphed by the same map, thickness rescaled by Eq. 5; skull landmarks
   covered by muscles are brought onto the muscle surface by cylindrical projection and
   the fit is run again (the refit), so the muscles lie at least ``muscle_gap_mm``
   beneath the skin there. Before that, with ``mouth_follows_lips`` (experimental, off by
   default), the muscle map (not the skull) around the mouth is shifted so that the lips'
   bone counterparts come in front of the skin's lips (:mod:`faceforge.fit.mouth`):
   the lips are no skull targets, and the orbicularis oris otherwise lands where the
   template's mouth sits on its teeth.
6. **Eye sockets** (:mod:`faceforge.fit.orbits`): where the skin models the closed
   eye socket (a pocket behind the lids), the bone inside the pocket moves out along rays
   from the pocket's centre, by a one-to-one map that cannot fold the thin orbital walls
   (pushing single bone vertices out does). Heads without a socket are left alone.
7. **Clearance** (:mod:`faceforge.fit.clearance`): where the bone still swallows
   skin, it gives way locally (compact bumps of ``clearance_radius``, each pushing the
   closest bone point to ``skin_clearance_mm`` beneath the skin vertex; the bumps sit on the
   corners of the closest face of the bones' common outer surface) until no skin vertex is
   inside or ``clearance_rounds`` is reached; the muscles, landmarks and axes move with it.

The map is kept as a composition of callables (similarity, RBF, enhancement flows, refit
RBF, orbit maps, clearance fields) and is applied to every template point: cranium, mandible, landmarks,
muscle-map points and the jaw axes' points; the axes' directions turn with the best rotation of the whole
mandible (the jaw is one rigid body).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from faceforge.anatomy import tissue as fit_tissue
from faceforge.fit.align import Warp
from faceforge.fit.skull import fit_skull, skull_targets
from faceforge.fit.surface import SkinSurface


@dataclass(frozen=True)
class FitSettings:
    """Parameters of the fit (config section ``fit``)."""

    tissue_depth: bool = True          # move skin targets inward by tissue depth
    tissue_normal_radius: float = 0.1  # a landmark on a fold takes the normal of the skin within this (x ES0); 0: off
    enhancement_rays: bool = True      # add ray-cast enhancement landmarks
    refit: bool = True                 # cylindrical projection onto muscles and second fit
    enhancement_rounds: int = 3
    enhancement_samples: int = 48      # new pairs considered per round
    enhancement_spacing: float = 0.035  # min distance between RBF sources, fraction of skin diagonal
    enhancement_min_ratio: float = 0.7  # add a pair where thickness < ratio * expected depth
    enhancement_cell: float = 0.015    # candidates: one skull vertex per cell of this size (x skin diagonal)
    enhancement_flow_steps: int = 8    # >0: each enhancement round is a flow of this many midpoint steps; 0: exact RBF
    enhancement_max_step: float = 0.25  # a flow moves a new pair at most this x its distance to the nearest held target
    skin_clearance_mm: float = 1.0     # skin found inside the bone is cleared by this much (mm); 0: off
    skin_clearance_samples: int = 16   # bone pairs per round for skin inside the bone
    front_offset_es0: float = 0.75     # front region: in front of eye corners minus this * ES0
    muscle_gap_mm: float = 1.5         # skin tissue kept above the muscle top at landmarks (mm)
    clearance_radius: float = 0.03     # bone bends around skin it swallowed within this (x skin diagonal)
    clearance_rounds: int = 6          # at most this many bump fields (fit_clearance)
    orbit_hollow: bool = True          # clear bone out of modelled eye sockets (fit_orbits)
    orbit_blend: float = 0.5           # the orbit map fades out over this fraction of the socket radius
    mouth_follows_lips: bool = False   # the muscle map around the mouth follows the skin's lips (fit_mouth)

    @classmethod
    def from_config(cls, cfg: dict | None) -> "FitSettings":
        """From the config's ``fit`` section (validated against configs/default.yaml)."""
        cfg = dict(cfg or {})
        kernel = cfg.pop("rbf_kernel", "multiquadric")
        if kernel != "multiquadric":
            from faceforge.exceptions import ConfigError

            raise ConfigError(f"fit.rbf_kernel: only 'multiquadric' (Hardy, §4) is implemented, got {kernel!r}")
        known = {k: v for k, v in cfg.items() if k in cls.__dataclass_fields__}
        return cls(**known)


# ----------------------------------------------------------------------------- the whole fit


@dataclass
class FitTemplate:
    """Template inputs of :func:`fit_head`, all in template (skull) space.

    cranium, mandible : (vertices (n, 3) float64, faces (m, 3) int64)
    landmarks : {fdp: (3,) float64} points on the bone
    jaw_axes : {name: (point (3,), direction (3,))} e.g. pitch, yaw, protrusion
    muscle_points : {muscle name: (k, 3) float64} every point of the muscle map
    muscle_weights : {muscle name: (k,) float64} how much of the mouth's shift each of those
        points takes (:func:`faceforge.fit.mouth.point_weights`; missing: all)
    """

    cranium: tuple
    mandible: tuple
    landmarks: dict
    jaw_axes: dict = field(default_factory=dict)
    muscle_points: dict = field(default_factory=dict)
    muscle_weights: dict = field(default_factory=dict)


@dataclass
class FitResult:
    """Everything :func:`fit_head` produced, in head space (mesh units)."""

    cranium: np.ndarray                 # (n, 3) fitted cranium vertices (template faces)
    mandible: np.ndarray                # (n, 3) fitted mandible vertices
    landmarks: dict                     # {fdp: (3,)} fitted bone landmarks
    fdps: tuple                         # FDPs used as skull targets
    targets: np.ndarray                 # (n, 3) final bone-landmark targets (after the refit)
    reached: np.ndarray                 # (n, 3) where those landmarks ended up
    jaw_axes: dict                      # {name: (point (3,), unit direction (3,))}
    muscle_points: dict                 # {name: (k, 3)} morphed muscle map
    muscles: list                       # [(name, vertices, faces)] built on the fitted skull
    warp: Warp
    info: dict                          # counts for the report
    cranium_faces: np.ndarray = None    # (m, 3) template faces
    mandible_faces: np.ndarray = None
    tissue_targets: np.ndarray = None   # (n, 3) targets before the refit (skin - depth * normal)
    enhancement_targets: np.ndarray = None  # (e, 3) where the enhancement landmarks went
    mirror: object = None               # faceforge.geometry.mirror.Mirror of a symmetric rig, else None


def fit_head(template: FitTemplate, skin: SkinSurface, skin_ids, skin_points,
             settings: FitSettings = FitSettings(), build_muscles: Callable | None = None,
             mirror=None) -> FitResult:
    """Fit the skull and muscle map into the skin (steps 1-5 of the module docstring).

    skin_ids (n,) FDP ids, skin_points (n, 3): the validated skin landmarks
    (:class:`faceforge.io.landmarks.Landmarks`); normals are taken where each lies on ``skin``.
    ``build_muscles(cranium (v, f), mandible (v, f), warp, shift) -> [(name, vertices, faces)]``
    builds the muscles on the fitted skull (Eq. 5 thickness), ``shift`` the mouth's
    (:class:`faceforge.fit.mouth.MouthField` or None, weighted per muscle particle);
    without it the muscle map points are morphed only and there is no refit. ``mirror``
    (:class:`faceforge.fit.symmetry.Mirror`, for a mirror-symmetric skin): the rig is made
    symmetric about it before the bone is cleared off the skin.
    """
    skin_lm = {f: np.asarray(p, dtype=np.float64) for f, p in zip(skin_ids, skin_points)}
    scale_mm = fit_tissue.units_per_mm(skin_lm)
    pairs = skull_targets(template.landmarks, skin, skin_ids, skin_points,
                          scale_mm, settings.tissue_depth, settings.tissue_normal_radius * fit_tissue.es0(skin_lm))
    (cv, cf), (mv, mf) = template.cranium, template.mandible
    skull_v = np.vstack([cv, mv])
    skull_f = np.vstack([cf, mf + len(cv)])
    sk = fit_skull(pairs, skull_v, skull_f, skin, skin_lm, settings, scale_mm)
    warp = sk.warp
    skull_fit = warp(skull_v)
    muscles = []
    targets = pairs.target
    info = {"units_per_mm": scale_mm, "landmark_pairs": len(pairs.fdps), "enhancement_rounds": sk.rounds,
            "anchors": int(len(pairs.anchors)),
            "enhancement_landmarks": int(len(sk.sources) - sk.n_landmarks - len(pairs.anchors)),
            "covered_landmarks": [],
            "refit": False}
    mouth = _mouth_shift(template, warp, skin_lm, skin.diagonal, info) if settings.mouth_follows_lips else None
    if build_muscles is not None:
        muscles = build_muscles((skull_fit[:len(cv)], cf), (skull_fit[len(cv):], mf), warp, mouth)
        if settings.refit and muscles:
            g2, refit_targets = _refit(skin, settings, pairs, sk, scale_mm, skull_fit, len(cv), muscles, info)
            if g2 is not None:
                warp = Warp(warp.similarity, warp.rbfs + [g2])
                skull_fit, muscles, targets = g2(skull_fit), _moved(muscles, [g2]), refit_targets
    partners = None
    if mirror is not None:   # a symmetric skin gets a symmetric rig
        from faceforge.fit.symmetry import bone_partners, symmetrize_bones

        partners = bone_partners(cv, mv)
        skull_fit, muscles = symmetrize_bones(skull_fit, len(cv), cf, mf, muscles, mirror, partners)
    # 6a. a modelled eye socket is hollow (fit_orbits): bone inside it moves out along rays from
    # the socket's centre, by a one-to-one map that cannot fold the orbital walls
    if settings.skin_clearance_mm > 0 and settings.orbit_hollow:
        hollows, skull_fit, shift = _orbit_hollows(skin, skin_lm, settings, scale_mm, skull_fit, skull_f)
        muscles, targets = _moved(muscles, hollows), _through(hollows, targets)
        warp = Warp(warp.similarity, warp.rbfs + hollows)
        info["orbit_hollows"] = len(hollows)
        info["orbit_clearance"] = [h.clearance for h in hollows]
        info["orbit_max_shift_rel"] = shift / skin.diagonal
    # the eye sockets are fitted per side: pair the bone again before the clearance, which has the
    # last word (pairing after it halved a push one side got more of: 2 MakeHuman midline nose
    # vertices ended 0.3 mm inside the bone); the clearance sees both sides' skin on both sides,
    # so its fields are as symmetric as the skin
    if partners is not None:
        from faceforge.fit.symmetry import pairs_halfway

        skull_fit = pairs_halfway(skull_fit, partners, mirror)
    # 6b. bone that still swallows skin gives way locally (fit_clearance); the same fields move
    # the muscles, landmarks and axes, so everything lying on the bone stays on it
    if settings.skin_clearance_mm > 0 and settings.clearance_rounds > 0:
        fields, skull_fit = _clearance(skin, settings, scale_mm, skull_fit, len(cv), cf, mf,
                                       mirror if partners is not None else None)
        muscles, targets = _moved(muscles, fields), _through(fields, targets)
        warp = Warp(warp.similarity, warp.rbfs + fields)
        info["clearance_fields"] = len(fields)
        info["clearance_points"] = int(sum(len(g.centres) for g in fields))
    # axes: points by the fit's similarity, directions by the bones' best rotations (fit/jaw.py)
    from faceforge.fit.jaw import fit_jaw_axes

    jaw = fit_jaw_axes(template.jaw_axes, warp.similarity, (cv, skull_fit[:len(cv)]), (mv, skull_fit[len(cv):]))
    fitted_lm = {f: warp(np.asarray(p, dtype=np.float64)[None])[0] for f, p in template.landmarks.items()}
    enhancement = sk.reached[sk.n_landmarks + len(pairs.anchors):]
    later = warp.rbfs[len(sk.warp.rbfs):]   # the refit, orbit and clearance maps carry them on
    enhancement = _through(later, enhancement)
    reached = np.array([fitted_lm[f] for f in pairs.fdps])

    def muscle_map(name, points):   # the skull's map, the mouth's shift (muscles only), the rest
        out = sk.warp(points)
        if mouth is not None:
            out = mouth(out, template.muscle_weights.get(name))
        return _through(later, out)

    result = FitResult(skull_fit[:len(cv)], skull_fit[len(cv):], fitted_lm, pairs.fdps, targets, reached, jaw,
                       {n: muscle_map(n, p) for n, p in template.muscle_points.items()}, muscles, warp, info,
                       np.asarray(cf), np.asarray(mf), pairs.target, enhancement)
    if mirror is not None:
        from faceforge.fit.symmetry import point_partners, symmetrize_fit

        result = symmetrize_fit(result, mirror, point_partners(template.muscle_points))
    return result


def _through(maps, points: np.ndarray) -> np.ndarray:
    """``points (k, 3)`` carried through each map of ``maps`` in turn."""
    for g in maps:
        points = g(points)
    return points


def _moved(muscles: list, maps) -> list:
    """Muscles ``[(name, vertices (v, 3), faces)]`` carried through ``maps`` in turn."""
    return [(n, _through(maps, v), f) for n, v, f in muscles]


def _mouth_shift(template: FitTemplate, warp, skin_lm: dict, diagonal: float, info: dict):
    """The mouth's shift (:func:`faceforge.fit.mouth.mouth_field`): the template's lip landmarks,
    placed by the skull's ``warp``, onto the skin's ``skin_lm``; None when there is nothing to
    move. Records ``mouth_shift_max_rel`` (of the skin's ``diagonal``) in ``info``."""
    from faceforge.fit.mouth import mouth_field

    names = list(template.landmarks)
    placed = warp(np.array([template.landmarks[f] for f in names], dtype=np.float64).reshape(-1, 3))
    mouth = mouth_field(dict(zip(names, placed)), skin_lm)
    if mouth is not None:
        info["mouth_shift_max_rel"] = float(np.linalg.norm(mouth.shifts, axis=1).max() / diagonal)
    return mouth


def _refit(skin: SkinSurface, settings: FitSettings, pairs, sk, scale_mm: float, skull_fit: np.ndarray,
           n_cranium: int, muscles: list, info: dict):
    """Step 5, the refit: skull landmarks the muscles cover move to keep the muscles' gap under the
    skin (:mod:`faceforge.fit.muscles`). Returns the refit's RBF (None when nothing moves) and the
    skull targets it meets; records ``covered_landmarks``, ``refit`` and ``refit_moved`` in
    ``info``."""
    from faceforge.fit import muscles as fit_muscles

    diag = float(np.linalg.norm(np.ptp(skull_fit, axis=0)))
    fitted = sk.warp(pairs.source)
    rf = fit_muscles.refit_pairs(fitted, skin, fit_muscles.vertical_axis(skull_fit[:n_cranium]),
                                 [(v, f) for _, v, f in muscles], settings.muscle_gap_mm * scale_mm,
                                 skin.diagonal, 0.05 * diag)
    g2 = fit_muscles.refit_rbf(rf, fitted, sk.reached[sk.n_landmarks:], sk.epsilon)
    info["covered_landmarks"] = [f for f, c in zip(pairs.fdps, rf.covered) if c]
    if g2 is not None:
        info["refit"] = True
        info["refit_moved"] = [f for f, d in zip(pairs.fdps, rf.delta) if np.any(d)]
    return g2, rf.skull_targets


def _orbit_hollows(skin: SkinSurface, skin_lm: dict, settings: FitSettings, scale_mm: float,
                   skull_fit: np.ndarray, skull_f: np.ndarray):
    """Step 6a: the hollow of each modelled eye socket (:mod:`faceforge.fit.orbits`), fitted in
    turn on the bone as the ones before left it. Returns (the hollows' maps, the moved bone
    ``(v, 3)``, the largest shift in skin units)."""
    from faceforge.fit.orbits import find_orbit_hollows, fit_hollow

    hollows, shift = [], 0.0
    for h in find_orbit_hollows(skin, skin_lm, settings.skin_clearance_mm * scale_mm, settings.orbit_blend):
        h = fit_hollow(h, skull_fit, skull_f)
        if h.lam >= 1.0:
            continue
        moved = h(skull_fit)
        shift = max(shift, float(np.linalg.norm(moved - skull_fit, axis=1).max()))
        skull_fit = moved
        hollows.append(h)
    return hollows, skull_fit, shift


def _clearance(skin: SkinSurface, settings: FitSettings, scale_mm: float, skull_fit: np.ndarray,
               n_cranium: int, cf: np.ndarray, mf: np.ndarray, mirror=None):
    """Step 6b: bone that still swallows skin gives way locally (:mod:`faceforge.fit.clearance`).
    With ``mirror`` (a symmetric rig) the fields carry their mirror images first (the bone stays
    symmetric), then plain fields clear the skin those cannot (a midline point inside a bony
    septum whose walls face sideways: mirrored pushes cancel there; 1 MakeHuman nose vertex by
    0.05 mm). Returns (the fields, the moved bone ``(v, 3)``)."""
    from faceforge.fit.clearance import clearance_fields

    used = np.unique(skin.faces)
    own = skin.vertices[used[used < skin.n_real]] if skin.n_real >= 0 else skin.vertices[used]
    if mirror is not None:
        own = np.vstack([own, mirror(own)])
    fields = []
    for sym in ((True, False) if mirror is not None else (False,)):
        more = clearance_fields([(skull_fit[:n_cranium], cf), (skull_fit[n_cranium:], mf)], own,
                                settings.skin_clearance_mm * scale_mm,
                                settings.clearance_radius * skin.diagonal, settings.clearance_rounds,
                                mirror=mirror if sym else None)
        skull_fit = _through(more, skull_fit)
        fields += more
    return fields, skull_fit
