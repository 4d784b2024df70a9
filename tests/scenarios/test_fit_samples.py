"""Scenario tests on the three sample heads: the acceptance criteria of issue 5.

Each head is fitted once per session (``fitted`` fixture). The heads differ on purpose:
decimetres and a closed head (MakeHuman), centimetres with open eyes and mouth (ICT), and
a 468-vertex open face mask with 46 FDPs (MediaPipe).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.fit.heads import SAMPLES

HEADS = sorted(SAMPLES)


@pytest.mark.parametrize("name", HEADS)
def test_skull_landmarks_reach_their_targets(fitted, name):
    result, report, _ = fitted(name)
    assert report["landmarks"]["max_residual"] < 0.01
    assert len(result.fdps) >= 10
    # the refit may move a target inward, but only by a few millimetres
    assert max(report["landmarks"]["refit_shift_rel"].values()) < 0.02


@pytest.mark.parametrize("name", HEADS)
def test_front_skull_inside_the_skin(fitted, name):
    _, report, _ = fitted(name)
    skull = report["skull"]
    assert skull["count"] > 1000
    assert skull["inside_fraction"] >= 0.98
    # median bone depth is a plausible soft-tissue thickness (2-25 mm of an average adult)
    assert 2.0 < report["tissue_thickness"]["median_mm"] < 25.0


@pytest.mark.parametrize("name", HEADS)
def test_bone_does_not_swallow_the_skin(fitted, name):
    """Deep eye sockets and nostrils must not end up inside the bone (bind needs skin outside)."""
    _, report, _ = fitted(name)
    assert report["skin_inside_bone"]["count"] == 0


#: most triangles (cranium, mandible) the fitted bone may turn over, relative to the template
#: turned by the similarity. Measured with the enhancement flow (the default,
#: enhancement_flow_steps: 8): MakeHuman 140, 10; ICT 0, 0; MediaPipe 9, 10. With the paper's
#: exact RBF through every enhancement pair (enhancement_flow_steps: 0): 250, 64; 7, 0; 37, 5.
TURNED_OVER = {"makehuman": (180, 20), "ict": (3, 3), "mediapipe": (20, 16)}
#: The template bone became its own mirror image (its right half re-triangulated, issue 25);
#: with it MakeHuman's exact-RBF fit turns over 279, 78 (was 250, 64 on the old template): the
#: limits below were 265, 70 and are now 5 % above the new figures, a loosening for a new mesh.
TURNED_OVER_EXACT = {"makehuman": (295, 82), "ict": (10, 2), "mediapipe": (42, 8)}


def turned_over_counts(result, template) -> list:
    """[cranium, mandible]: fitted triangles whose normal turned against the template's."""
    rot = result.warp.similarity[:3, :3]

    def normals(v, f):
        t = np.asarray(v)[f]
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])

    ft = template.fit_template
    return [int((np.einsum("ij,ij->i", normals(tv, tf) @ rot.T, normals(fitted_v, tf)) < 0).sum())
            for (tv, tf), fitted_v in ((ft.cranium, result.cranium), (ft.mandible, result.mandible))]


@pytest.mark.parametrize("name", HEADS)
def test_fitted_bone_turns_over_few_triangles(fitted, template, name):
    """§7: the map template -> head should be one-to-one; a triangle whose normal turns
    against the template's marks a fold of the bone surface (thin bone pushed through itself).
    The enhancement flow (the default) folds few (only triangles larger than the field's
    detail); the paper's exact RBF, still an option, folds more and still fits."""
    from faceforge.fit.files import fit_files

    counts = turned_over_counts(fitted(name)[0], template)
    assert all(c <= limit for c, limit in zip(counts, TURNED_OVER[name])), (name, counts)
    mesh = SAMPLES[name]
    exact, report, _ = fit_files(mesh, mesh.with_name(mesh.stem + ".fdp.yaml"), template,
                                 {"enhancement_flow_steps": 0, "symmetric_tolerance": 0})
    # (the exact RBF's own folds; made symmetric as well it left 2 MakeHuman skin vertices in the bone)
    counts = turned_over_counts(exact, template)
    assert all(c <= limit for c, limit in zip(counts, TURNED_OVER_EXACT[name])), (name, counts)
    assert all(report["checks"].values()) and report["skin_inside_bone"]["count"] == 0


@pytest.mark.parametrize("name", HEADS)
def test_modelled_eye_sockets_stay_hollow(fitted, name):
    """MakeHuman models the closed eye socket (a skin pocket behind the lids): the fitted
    bone keeps out of it, and the map that clears it moves the bone by little. Heads with
    eye holes and no socket (ICT, MediaPipe) have no hollow and no such map."""
    from faceforge.fit.surface import SkinSurface
    from faceforge.fit.orbits import find_orbit_hollows

    result, report, extra = fitted(name)
    checked = extra["checked"]
    skin = SkinSurface.build(checked.vertices, checked.faces)
    hollows = find_orbit_hollows(skin, extra["landmarks"].as_dict(), report["units_per_mm"])
    assert len(hollows) == (2 if name == "makehuman" else 0)
    assert result.info["orbit_hollows"] == len(hollows)
    # (0.023 of the diagonal before the enhancement flows' step limit; with it the flows push
    # less bone out of the socket and this map more: 0.045, one-to-one either way, and the
    # whole fit turns over 67 cranium triangles instead of 145; 0.052 on the mirror-image
    # template bone of issue 25, so the bound went from 0.05 to 0.055)
    assert result.info["orbit_max_shift_rel"] < 0.055
    bone = np.vstack([result.cranium, result.mandible])
    for h in hollows:
        # the skin of the pocket holds the centre: it lies behind the eye corners
        assert h.centre[2] < max(extra["landmarks"].as_dict()[k][2] for k in ("3.7", "3.11", "3.8", "3.12"))
        assert not h.inside(bone).any()


@pytest.mark.parametrize("name", HEADS)
def test_muscles_inside_the_skin(fitted, name):
    result, report, _ = fitted(name)
    m = report["muscles"]
    assert len(result.muscles) == 32 and m["count"] > 500
    assert m["inside_fraction"] >= 0.98
    assert m["max_outside_rel"] <= 0.01


@pytest.mark.parametrize("name", HEADS)
def test_fitted_skull_keeps_its_anatomy(fitted, name):
    result, report, extra = fitted(name)
    lm = result.landmarks
    # left stays left, chin below the eyes, nose base in front of the ear line
    for left, right in (("3.7", "3.12"), ("2.13", "2.14"), ("4.3", "4.4")):
        assert lm[left][0] > lm[right][0]
    assert lm["2.1"][1] < lm["3.7"][1]
    # jaw axes: unit directions; the pitch axis still runs across the head (+X)
    for name_, (point, direction) in result.jaw_axes.items():
        assert np.isclose(np.linalg.norm(direction), 1.0)
        assert np.all(np.isfinite(point))
    assert result.jaw_axes["pitch"][1][0] > 0.99
    # the jaw turns about the condyles: below the eyes, behind the outer eye corners, above the
    # chin (the full map once put MakeHuman's pitch axis above the pupils)
    skin = extra["landmarks"].as_dict()
    pivot = result.jaw_axes["pitch"][0]
    assert pivot[1] < min(skin["3.7"][1], skin["3.12"][1]) - 0.1 * abs(skin["3.7"][0] - skin["3.12"][0])
    assert pivot[2] < min(skin["3.7"][2], skin["3.12"][2]) and pivot[1] > skin["2.1"][1]
    # Eq. 5: muscle thickness scales with the fitted skull, not with the template
    skull = np.vstack([result.cranium, result.mandible])
    ratio = np.linalg.norm(np.ptp(skull, axis=0)) / extra["template"].skull.diagonal
    assert np.isclose(report["similarity_scale"], ratio, rtol=0.35)


def test_stage_files_are_what_bind_reads(fitted, tmp_path):
    from faceforge.pipeline.stages.bind import load_fit
    from faceforge.pipeline.stages.fit import write_outputs

    result, report, extra = fitted("mediapipe")
    write_outputs(tmp_path, result, report, extra)
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    head = load_fit(tmp_path)
    np.testing.assert_array_equal(head["vertices"], extra["checked"].vertices)
    assert len(head["muscles"]) == 32
    np.testing.assert_allclose(head["cranium"][0], result.cranium)
    import json

    rep = json.loads((tmp_path / "report.json").read_text())
    assert rep["skull"]["inside_fraction"] == report["skull"]["inside_fraction"]
    # the fitted muscle map loads with the fitted skull and holds the morphed points, put on
    # that skull as every muscle map's points are (the mouth's shift moves some off it)
    from dataclasses import replace

    from faceforge.anatomy.muscles.muscle_map import SkullProjector, load_muscle_map

    skull = replace(extra["template"].skull, cranium=(result.cranium, result.cranium_faces),
                    mandible=(result.mandible, result.mandible_faces), landmarks=result.landmarks,
                    _diagonal=None)
    specs = load_muscle_map(tmp_path / "muscle_map.yaml", skull)
    assert [s.name for s in specs] == [s.name for s in extra["template"].specs]
    project = SkullProjector(skull)
    for spec in specs:
        moved = project(result.muscle_points[spec.name])[0]
        assert np.max(np.linalg.norm(spec.points() - moved, axis=1)) < 1e-6 * report["diagonal"]


def test_units_and_pose_do_not_matter(template, fitted, tmp_path):
    """The MediaPipe head in millimetres, turned 8 degrees about Y and moved: the same fit."""
    from faceforge.io.mesh import load_mesh, save_mesh
    from faceforge.io.stagefiles import load_yaml, save_yaml
    from faceforge.fit.files import fit_files

    base, base_report, _ = fitted("mediapipe")
    v, f, _ = load_mesh(SAMPLES["mediapipe"])
    a = np.radians(8.0)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    move = lambda p: 10.0 * np.asarray(p) @ rot.T + [3.0, -20.0, 5.0]   # cm -> mm
    save_mesh(tmp_path / "head.obj", move(v), f)
    lm = load_yaml(SAMPLES["mediapipe"].with_name("face_model_with_iris.fdp.yaml"))
    for entry in lm["landmarks"].values():
        entry["position"] = move(entry["position"]).tolist()
    save_yaml(tmp_path / "head.fdp.yaml", lm)
    result, report, _ = fit_files(tmp_path / "head.obj", tmp_path / "head.fdp.yaml", template, {})
    assert report["skull"]["inside_fraction"] >= 0.98 and report["landmarks"]["max_residual"] < 0.01
    back = (np.vstack([result.cranium, result.mandible]) - [3.0, -20.0, 5.0]) @ rot / 10.0
    ref = np.vstack([base.cranium, base.mandible])
    err = np.linalg.norm(back - ref, axis=1) / base_report["diagonal"]
    assert np.median(err) < 0.01


def test_same_inputs_same_fit(fitted, template):
    """Deterministic: a second fit of the same head gives identical arrays."""
    from faceforge.fit.files import fit_files

    first, report, _ = fitted("mediapipe")
    mesh = SAMPLES["mediapipe"]
    again, report2, _ = fit_files(mesh, mesh.with_name(mesh.stem + ".fdp.yaml"), template, {})
    np.testing.assert_array_equal(first.cranium, again.cranium)
    np.testing.assert_array_equal(first.mandible, again.mandible)
    for (n1, v1, _), (n2, v2, _) in zip(first.muscles, again.muscles):
        assert n1 == n2
        np.testing.assert_array_equal(v1, v2)
    assert all(report["checks"].values()) and report2["checks"] == report["checks"]


def test_symmetric_skin_gets_a_symmetric_rig(template):
    """With ``fit.symmetric_tolerance`` (opt-in, 0.002 suits the samples) a
    mirror-symmetric skin (MediaPipe's) gets its bones, muscle map and jaw axes made
    mirror-symmetric, keeps the plane, and its right muscles are the mirror images of the left."""
    from faceforge.fit.files import fit_files
    from faceforge.fit.symmetry import mirror_plane
    from faceforge.geometry.closest import TriangleGrid

    mesh = SAMPLES["mediapipe"]
    result, report, extra = fit_files(mesh, mesh.with_name(mesh.stem + ".fdp.yaml"), template,
                                      {"symmetric_tolerance": 0.01})
    assert report["symmetric_rig"]["made_symmetric"]
    mirror, es0 = mirror_plane(extra["landmarks"].as_dict())
    for bone, faces in ((result.cranium, result.cranium_faces), (result.mandible, result.mandible_faces)):
        q, _ = TriangleGrid(mirror(bone)[faces]).closest(bone)
        assert np.linalg.norm(q - bone, axis=1).mean() < 0.005 * es0
    for left in [n for n in result.muscle_points if n.endswith("_L")]:
        assert np.allclose(mirror(result.muscle_points[left]), result.muscle_points[left[:-2] + "_R"])
    assert abs(result.jaw_axes["pitch"][0] - mirror(result.jaw_axes["pitch"][0][None])[0]).max() < 1e-9 * es0
    assert report["skin_inside_bone"]["count"] == 0
    assert result.mirror is not None
    muscles = {n: v for n, v, _ in result.muscles}
    for left in [n for n in muscles if n.endswith("_L")]:
        # built on the bone, which is symmetric to its mesh only (measured: 0.0008-0.012 ES0
        # mean, at worst 0.124 for the masseter on the mask's extrapolated skull sides)
        gap = np.linalg.norm(mirror(muscles[left]) - muscles[left[:-2] + "_R"], axis=1)
        assert gap.mean() < 0.02 * es0 and gap.max() < 0.2 * es0, (left, gap.mean() / es0, gap.max() / es0)


def test_fapu_come_from_the_landmarks_as_given(fitted, tmp_path):
    """ICT has no eyeballs: its pupils (3.5, 3.6) are given in the eye openings, and snapping
    puts them on the lids; fit.npz keeps them as given, and the FAPU are measured on those."""
    import yaml

    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import fapu_from_landmarks
    from faceforge.pipeline.stages.fit import write_outputs

    result, report, extra = fitted("ict")
    write_outputs(tmp_path, result, report, extra)
    fit = load_npz(tmp_path / "fit.npz")
    given = dict(zip(fit["given_landmark_ids"], fit["given_landmark_positions"]))
    snapped = dict(zip(fit["skin_landmark_ids"], fit["skin_landmark_positions"]))
    doc = yaml.safe_load(SAMPLES["ict"].with_name(SAMPLES["ict"].stem + ".fdp.yaml").read_text())
    assert np.allclose(given["3.5"], doc["landmarks"]["3.5"]["position"])
    assert given["3.5"][1] - snapped["3.5"][1] > 0.3, "snapping moved the pupil down onto the lid"
    ens_given = fapu_from_landmarks({**snapped, **given}).ens0
    assert ens_given > 1.05 * fapu_from_landmarks(snapped).ens0


def test_a_fit_that_fails_its_checks_is_fitted_again_on_smoothed_normals(template, monkeypatch):
    """``noisy_normal_rounds``: a fit that fails a check on the raw normals is done once more on normals
    averaged over neighbours and kept when it fails fewer (said in the log, ``normal_rounds`` in the report);
    a fit that passes is not redone. Here the check fails whenever the normals are the raw ones (a stand-in
    for a scan's noise: the noisy MakeHuman of docs/notes/scan19.md, measured through the CLI)."""
    import faceforge.fit.report as fit_report
    from faceforge.fit.files import fit_files
    from faceforge.geometry.triangles import vertex_normals

    real = fit_report.build_report

    def noisy(result, skin, *args, **kw):
        report = real(result, skin, *args, **kw)
        raw = np.allclose(skin.normals, vertex_normals(skin.vertices, skin.faces))
        report["checks"]["muscles_poke_below_1pct"] = not raw
        return report

    monkeypatch.setattr(fit_report, "build_report", noisy)
    mesh = SAMPLES["mediapipe"]
    lm = mesh.with_name(mesh.stem + ".fdp.yaml")
    _, off, _ = fit_files(mesh, lm, template, {"noisy_normal_rounds": 0})
    assert not off["checks"]["muscles_poke_below_1pct"] and off["normal_rounds"] == 0
    said = []
    _, again, _ = fit_files(mesh, lm, template, {"noisy_normal_rounds": 3}, log=said.append)
    assert all(again["checks"].values()) and again["normal_rounds"] == 3
    assert any("averaged over 3 rounds" in line and "passes: kept" in line for line in said)
    monkeypatch.setattr(fit_report, "build_report", real)
    said.clear()
    _, clean, _ = fit_files(mesh, lm, template, {"noisy_normal_rounds": 3}, log=said.append)
    assert clean["normal_rounds"] == 0 and not any("rounds" in line for line in said)
