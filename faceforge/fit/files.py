"""Fitting a head from its files: the mesh and its landmarks, checked and turned into head
space, then :func:`faceforge.fit.head.fit_head` with the template (§7)."""

from __future__ import annotations

from faceforge.fit.orientation import head_orientation
from faceforge.fit.template import Template


def fit_files(mesh_path, lm_path, template: Template, fit_config: dict, log=lambda m: None):
    """Load and check the skin and its landmarks, fit ``template``.

    Returns ``(FitResult, report dict, extra)``; ``extra`` holds the checked mesh and the
    landmarks for :func:`write_outputs`.
    """
    import time

    from faceforge.fit.head import FitSettings, fit_head
    from faceforge.fit.surface import SkinSurface, orient_outward
    from faceforge.fit.report import build_report
    from faceforge.io.landmarks import load_landmarks, read_landmarks
    from faceforge.io.mesh import load_mesh
    from faceforge.io.mesh_check import check_mesh

    t = time.perf_counter()
    v, f, _ = load_mesh(mesh_path)
    checked = check_mesh(v, f, str(mesh_path))
    raw = read_landmarks(lm_path)
    straighten = float(fit_config.get("straighten_deg", 0.0))   # 0: off
    reference = None
    if straighten > 0:   # the template's own landmark frame: where an upright head's lies
        from faceforge.io.landmarks import points_frame

        reference = points_frame(template.fit_template.landmarks)
    orientation = head_orientation(fit_config.get("orientation", "auto"), raw, v, reference,
                                   straighten if straighten > 0 else None)
    if not orientation.identity:   # a signed permutation is exact: same head space bits as an upright mesh
        checked.vertices = checked.vertices @ orientation.rotation.T
        log(f"{mesh_path}: {orientation.describe()}")
    checked.faces = orient_outward(checked.vertices, checked.faces)   # stage files: outward winding
    for w in checked.report.warnings:
        log(f"{mesh_path}: {w}")
    simulation, lm_raw = None, raw
    limit = int(fit_config.get("simulation_vertices", 0) or 0)
    from faceforge.fit.proxy import landmarks_by_position, make_proxy, needs_proxy

    if needs_proxy(len(checked.vertices), limit):   # a dense scan: fitted and simulated on a coarser copy
        from faceforge.fit.proxy import lip_contours, lip_lock

        dense = load_landmarks(lm_path, checked.vertices, checked.faces, user_to_internal=checked.user_to_internal,
                               rotation=None if orientation.identity else orientation.rotation, raw=raw)
        points = dict(zip(dense.ids, dense.positions))
        locked = lip_lock(checked.vertices, checked.faces, points,
                          corner_reach=float(fit_config.get("simulation_corner_lock", 0.0) or 0.0),
                          rings=int(fit_config.get("simulation_lock_rings", 1)),
                          contours=bool(fit_config.get("simulation_contour_lock", True)))
        contours = lip_contours(checked.vertices, checked.faces, points) if bool(
            fit_config.get("simulation_lip_sides", True)) and locked.any() else None
        checked, simulation = make_proxy(checked, f, limit, keep_borders=bool(fit_config.get("simulation_borders", True)),
                                         locked=locked, contours=contours)
        checked.faces = orient_outward(checked.vertices, checked.faces)
        lm_raw = landmarks_by_position(raw, v)
        log(f"{mesh_path}: {simulation.report['dense_vertices']} vertices, more than fit.simulation_vertices "
            f"{limit}: simulated on a copy of {len(checked.vertices)} vertices (the mesh's carried on it)")
    lm = load_landmarks(lm_path, checked.vertices, checked.faces,
                        user_to_internal=None if simulation is not None else checked.user_to_internal,
                        rotation=None if orientation.identity else orientation.rotation, raw=lm_raw)
    # animate measures the FAP units on these landmarks (pupils, eyelids, nose, mouth): a file
    # without them must fail here, not after fit and bind ran (issue 28)
    from faceforge.mpeg4 import fapu_from_landmarks

    fapu_from_landmarks(dict(zip(lm.ids, lm.positions)), lm_path)
    t_load = time.perf_counter() - t
    t = time.perf_counter()
    settings = FitSettings.from_config(fit_config)
    mirror = _skin_mirror(lm, checked.vertices, checked.faces, float(fit_config.get("symmetric_tolerance", 0.0)),
                          log)
    mesh_report = {"path": str(mesh_path), **checked.report.as_dict()}

    def fit_with(rounds: int):
        skin = SkinSurface.build(checked.vertices, checked.faces, normal_rounds=rounds)
        try:
            result = fit_head(template.fit_template, skin, lm.ids, lm.positions, settings, template.build_muscles,
                              mirror=mirror)
        except ValueError as exc:   # too few usable landmark pairs, degenerate configuration
            from faceforge.exceptions import LandmarkError

            raise LandmarkError(f"cannot fit the template: {exc}", lm_path) from None
        level = list(fit_config.get("level_muscles") or [])
        if level:   # soft-tissue origins keep the template's line of pull (fit.level)
            from faceforge.fit.level import level_map

            result = level_map(result, template.specs, level)
        if result.mirror is not None or level:   # bind sees the muscles the rig builds (fit.symmetry)
            from faceforge.fit.symmetry import rebuild_muscles

            result = rebuild_muscles(result, template.specs)
        return skin, result, build_report(result, skin, lm, mesh_report, settings.front_offset_es0)

    rounds = int(fit_config.get("normal_rounds", 0))
    skin, result, report = fit_with(rounds)
    retry = int(fit_config.get("noisy_normal_rounds", 0))
    failed = [k for k, ok in report["checks"].items() if not ok]
    if failed and retry > rounds:   # a noisy surface (a scan) tilts its vertex normals: fit once more, smoothed
        again = fit_with(retry)
        still = [k for k, ok in again[2]["checks"].items() if not ok]
        log(f"the fit failed {', '.join(failed)} on the skin's normals; with them averaged over {retry} rounds of "
            f"neighbours (fit.noisy_normal_rounds: a noisy surface?) it " + ("passes: kept" if not still else
                                                                            f"fails {', '.join(still)}"))
        if len(still) < len(failed):
            skin, result, report = again
            rounds = retry
    report["normal_rounds"] = rounds
    t_fit = time.perf_counter() - t
    t = time.perf_counter()
    report["settings"] = dict(settings.__dict__)
    report["orientation"] = orientation.as_dict()
    report["symmetric_rig"] = {"made_symmetric": mirror is not None,
                               "skin_asymmetry_es0": None if mirror is None else mirror.asymmetry_es0}
    gap = lip_gap_ratio(dict(zip(lm.ids, lm.positions)))
    report["mouth"]["rest_gap_mw"] = gap
    limit = float(fit_config.get("open_mouth_warn", 0.0))
    if limit > 0 and gap is not None and gap > limit:
        log(f"the mouth is open at rest (inner lips {gap:.2f} of the mouth's width apart, more than "
            f"fit.open_mouth_warn {limit:g}): it is taken as this head's neutral, so every FAP and expression "
            "starts from it and opens it further; the MPEG-4 neutral face has the lips closed")
    report["timings"] = {"load_s": t_load, "fit_s": t_fit, "report_s": time.perf_counter() - t}
    if simulation is not None:
        report["simulation_mesh"] = simulation.report
    return result, report, {"checked": checked, "landmarks": lm, "skin": skin, "template": template,
                            "orientation": orientation, "raw_landmarks": raw, "simulation": simulation}


def lip_gap_ratio(points: dict) -> float | None:
    """The inner lips' midpoints' distance (FDP 2.2 to 2.3) over the mouth's width (8.3 to 8.4),
    from ``{fdp: (3,)}`` positions (any one unit); None when a point is missing. Closed mouths:
    the samples 0.02-0.12 (MediaPipe's lips joined by a sheet the most); the MakeHuman sample's
    surprise frame taken as a neutral 0.28."""
    import numpy as np

    if not all(k in points for k in ("2.2", "2.3", "8.3", "8.4")):
        return None
    width = float(np.linalg.norm(np.subtract(points["8.3"], points["8.4"])))
    return float(np.linalg.norm(np.subtract(points["2.2"], points["2.3"])) / width) if width > 0 else None


def _skin_mirror(lm, vertices, faces, tolerance: float, log):
    """The skin's mirror (:class:`faceforge.fit.symmetry.Mirror`) when it is symmetric: every
    used vertex's mirror image lies within ``tolerance`` ES0 of a vertex; else None (also
    for ``tolerance`` 0: never)."""
    import numpy as np

    from faceforge.fit.symmetry import exact_plane, mirror_plane, skin_asymmetry

    plane = mirror_plane(dict(zip(lm.ids, lm.positions))) if tolerance > 0 else None
    if plane is None:
        return None
    mirror, es0 = plane
    used = np.asarray(vertices)[np.unique(faces)]
    if mirror.exact_partners(used) is None:   # the landmarks' plane may miss an exactly symmetric skin
        mirror = exact_plane(used, mirror) or mirror
    off = skin_asymmetry(used, mirror) / es0
    if off > tolerance:
        log(f"the skin is asymmetric ({off:.3f} ES0 from its mirror image): the rig is fitted as it is")
        return None
    mirror.asymmetry_es0 = off
    return mirror


def given_positions(raw, rotation) -> dict:
    """{fdp: (3,)} the positions the landmark file gives (head space), before snapping: a pupil
    of an eyeless mesh lies in the eye opening, and snapped it lands on a lid (FAPU use these)."""
    import numpy as np

    if raw is None:
        return {}
    return {str(k): np.asarray(p, dtype=float) @ np.asarray(rotation, dtype=float).T
            for k, p in zip(raw.ids, raw.position) if np.all(np.isfinite(p))}
