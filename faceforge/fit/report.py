"""Checks of a fit: how deep the skull and muscles lie beneath the skin.

Inside test (:func:`depth_below_skin`). For a watertight skin the sign comes from
ray parity (``trimesh.Trimesh.contains``). Heads are usually open (neck, eyes, mouth;
a face mask is all open), so otherwise the sign is that of the offset from the
closest skin point along the skin's smooth normal there (interpolated area-weighted
vertex normals): positive beneath the skin. A point whose closest skin point lies on
the skin's boundary (beyond the edge of a mask, through an eye hole) is *not covered*:
no skin is above it, so it is neither inside nor outside and is left out of the
fractions (the back of the skull need not fit, §7). A point on the outer side of its
closest skin point whose ray along that outward normal meets the skin again lies in a
pocket the skin wraps around (a modelled mouth cavity or eye socket: teeth and orbits
belong there) and counts as inside, at depth 0.
"""

from __future__ import annotations

import numpy as np


def depth_below_skin(points: np.ndarray, skin) -> tuple[np.ndarray, np.ndarray]:
    """Signed depth (k,) float (positive beneath the skin, head units; 0 in a pocket) and
    covered (k,) bool; see :func:`faceforge.fit.surface.signed_skin_depth`."""
    from faceforge.fit.surface import signed_skin_depth

    depth, _, _, covered, _ = signed_skin_depth(points, skin)
    return depth, covered


def inside_stats(depth: np.ndarray, covered: np.ndarray, diagonal: float, tol: float = 0.0) -> dict:
    """Summary of signed depths: fraction inside (depth > -tol), worst poke, min/median."""
    d = depth[covered]
    if len(d) == 0:
        return {"count": 0, "inside_fraction": None, "max_outside": 0.0, "max_outside_rel": 0.0,
                "min_depth": None, "median_depth": None}
    poke = float(max(0.0, -d.min()))
    return {
        "count": int(len(d)),
        "inside_fraction": float(np.mean(d >= -tol)),
        "max_outside": poke,
        "max_outside_rel": poke / diagonal,
        "min_depth": float(d.min()),
        "median_depth": float(np.median(d)),
    }


def landmark_residuals(fdps, reached: np.ndarray, targets: np.ndarray, diagonal: float) -> dict:
    """``{fdp: distance / diagonal}`` between reached (n, 3) and target (n, 3) points."""
    r = np.linalg.norm(np.asarray(reached) - np.asarray(targets), axis=1) / diagonal
    return {f: float(x) for f, x in zip(fdps, r)}


def build_report(result, skin, skin_landmarks, mesh_report: dict, front_offset_es0: float = 0.75) -> dict:
    """The fit report (JSON-friendly) of a :class:`faceforge.fit.head.FitResult`.

    Skull numbers cover the *front* vertices (in front of the coronal plane ``front_offset_es0``
    ES0 behind the outer eye corners) that the skin covers; muscle numbers cover every
    muscle vertex the skin covers. Depths are in head units and in millimetres of an
    average adult (``units_per_mm``).
    """
    from faceforge.fit.surface import front_mask

    diag = skin.diagonal
    mm = result.info["units_per_mm"]
    skin_lm = skin_landmarks.as_dict()
    from faceforge.fit.surface import signed_skin_depth

    skull = np.vstack([result.cranium, result.mandible])
    depth, _, _, covered, pocket = signed_skin_depth(skull, skin)
    front = front_mask(skull, skin_lm, front_offset_es0)
    skull_stats = inside_stats(depth, covered & front, diag)
    beneath = inside_stats(depth, covered & front & ~pocket, diag)   # thickness: pockets left out
    residuals = landmark_residuals(result.fdps, result.reached, result.targets, diag)
    muscles, per_muscle = [], {}
    all_depth, all_cov = [], []
    for name, v, _ in result.muscles:
        d, c = depth_below_skin(v, skin)
        all_depth.append(d)
        all_cov.append(c)
        st = inside_stats(d, c, diag)
        per_muscle[name] = {"inside_fraction": st["inside_fraction"], "max_outside_rel": st["max_outside_rel"]}
        if st["max_outside"] > 0:
            muscles.append(name)
    muscle_stats = inside_stats(np.concatenate(all_depth) if all_depth else np.zeros(0),
                                np.concatenate(all_cov) if all_cov else np.zeros(0, bool), diag)
    muscle_stats["per_muscle"] = per_muscle
    muscle_stats["poking_through"] = sorted(muscles, key=lambda n: -per_muscle[n]["max_outside_rel"])
    for st in (skull_stats, muscle_stats):
        for key in ("min_depth", "median_depth"):
            st[key + "_mm"] = None if st[key] is None else st[key] / mm
    from faceforge.fit.surface import inside_closed

    own = skin.vertices[:skin.n_real] if skin.n_real >= 0 else skin.vertices
    swallowed = np.zeros(len(own), bool)
    for v, f in ((result.cranium, result.cranium_faces), (result.mandible, result.mandible_faces)):
        if f is not None and len(f):
            swallowed |= inside_closed(v, f, own)
    sim = result.warp.similarity[:3, :3]
    return {
        "mesh": mesh_report,
        "diagonal": diag,
        "units_per_mm": mm,
        "similarity_scale": float(np.cbrt(abs(np.linalg.det(sim)))),
        "landmarks": {
            "file": skin_landmarks.path,
            "count": len(skin_landmarks.ids),
            "max_snap_rel": float(skin_landmarks.snap_distance.max() / diag),
            "skull_targets": list(result.fdps),
            "residuals_rel": residuals,
            "max_residual": max(residuals.values()) if residuals else 0.0,
            "refit_shift_rel": landmark_residuals(result.fdps, result.targets, result.tissue_targets, diag),
            "enhancement_landmarks": result.info["enhancement_landmarks"],
            "enhancement_rounds": result.info["enhancement_rounds"],
            "covered_by_muscles": result.info["covered_landmarks"],
            "refit": result.info["refit"],
        },
        "skull": skull_stats,
        "muscles": muscle_stats,
        "mouth": {"follows_lips": "mouth_shift_max_rel" in result.info,      # fit_mouth
                  "max_shift_rel": result.info.get("mouth_shift_max_rel")},
        "skin_inside_bone": {"count": int(swallowed.sum()), "fraction": float(swallowed.mean())},
        "checks": {   # the acceptance criteria of issue 5
            "landmarks_within_1pct": bool(max(residuals.values(), default=0.0) < 0.01),
            "skull_inside_98pct": bool((skull_stats["inside_fraction"] or 0.0) >= 0.98),
            "muscles_inside_98pct": bool(muscle_stats["count"] == 0 or muscle_stats["inside_fraction"] >= 0.98),
            "muscles_poke_below_1pct": bool(muscle_stats["max_outside_rel"] <= 0.01),
        },
        "tissue_thickness": {"min": beneath["min_depth"], "median": beneath["median_depth"],
                             "min_mm": None if beneath["min_depth"] is None else beneath["min_depth"] / mm,
                             "median_mm": None if beneath["median_depth"] is None else beneath["median_depth"] / mm,
                             "in_pockets": int((covered & front & pocket).sum())},
    }


def npz_arrays(result, skin_vertices, skin_faces, user_to_internal, skin_landmarks, layers: dict) -> dict:
    """The arrays of ``fit.npz`` (see :mod:`faceforge.pipeline.stages.fit`)."""
    out = {
        "skin_vertices": np.asarray(skin_vertices, np.float64),
        "skin_faces": np.asarray(skin_faces, np.int64),
        "skin_user_to_internal": np.asarray(user_to_internal, np.int64),
        "cranium_vertices": result.cranium, "cranium_faces": result.cranium_faces,
        "mandible_vertices": result.mandible, "mandible_faces": result.mandible_faces,
        "landmark_ids": np.array(list(result.landmarks), dtype=str),
        "landmark_positions": np.array(list(result.landmarks.values()), dtype=np.float64).reshape(-1, 3),
        "skin_landmark_ids": np.array(skin_landmarks.ids, dtype=str),
        "skin_landmark_positions": skin_landmarks.positions,
        "target_ids": np.array(result.fdps, dtype=str),
        "target_positions": result.targets,
        "similarity": result.warp.similarity,
    }
    for name, (point, direction) in result.jaw_axes.items():
        out[f"jaw_{name}_point"] = point
        out[f"jaw_{name}_direction"] = direction
    names = [n for n, _, _ in result.muscles]
    out["muscle_names"] = np.array(names, dtype=str)
    out["muscle_layers"] = np.array([layers.get(n, 0) for n in names], dtype=np.int64)
    out["muscle_vertex_start"] = np.cumsum([0] + [len(v) for _, v, _ in result.muscles]).astype(np.int64)
    out["muscle_face_start"] = np.cumsum([0] + [len(f) for _, _, f in result.muscles]).astype(np.int64)
    out["muscle_vertices"] = np.vstack([v for _, v, _ in result.muscles]) if names else np.zeros((0, 3))
    out["muscle_faces"] = np.vstack([f for _, _, f in result.muscles]).astype(np.int64) if names \
        else np.zeros((0, 3), np.int64)
    mp = list(result.muscle_points.items())
    out["muscle_map_names"] = np.array([n for n, _ in mp], dtype=str)
    out["muscle_map_start"] = np.cumsum([0] + [len(p) for _, p in mp]).astype(np.int64)
    out["muscle_map_points"] = np.vstack([p for _, p in mp]) if mp else np.zeros((0, 3))
    if getattr(result, "mirror", None) is not None:   # a symmetric rig: bind and animate keep it so
        out.update(result.mirror.as_arrays())
    return out
