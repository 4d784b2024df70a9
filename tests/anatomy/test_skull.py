"""The template skull (templates/skull/): meshes, FDP landmarks on the bone, the 3-DOF jaw."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from faceforge.anatomy.skull import (apply_transform, jaw_transform, load_skull, posed_landmarks,
                                     posed_mandible, rotation_about_axis)
from faceforge.exceptions import TemplateError

ROOT = Path(__file__).resolve().parents[2]
SKULL = ROOT / "templates" / "skull"


@pytest.fixture(scope="module")
def skull():
    return load_skull(SKULL)


def test_meshes_are_closed_outward_and_clean(skull):
    for name in ("cranium", "mandible"):
        v, f = getattr(skull, name)
        m = trimesh.Trimesh(v, f, process=False)
        assert m.is_watertight, name
        assert m.is_winding_consistent, name
        assert m.volume > 0, f"{name}: normals point inward"
        assert m.area_faces.min() > 1e-10 * skull.diagonal ** 2, f"{name}: degenerate face"
    n = len(skull.cranium[0]) + len(skull.mandible[0])
    assert 2000 < n < 8000, "a few thousand vertices in total"


def test_frame_life_size_y_up_face_forward(skull):
    v = np.concatenate([skull.cranium[0], skull.mandible[0]])
    height = np.ptp(v[:, 1])
    assert 18.0 < height < 26.0, "life size in cm (vertex to menton ~ 21 cm)"
    # the face looks along +Z: the chin and the brow ridge are in front of the skull's centre
    centre = v.mean(0)
    assert skull.landmarks["2.10"][2] > centre[2] + 5.0
    assert skull.landmarks["4.1"][2] > centre[2] + 5.0
    # Y up: the top of the skull is above the chin
    assert skull.landmarks["11.4"][1] > skull.landmarks["2.1"][1] + 15.0
    # midsagittal plane x = 0 (symmetric bounding box)
    assert abs(v[:, 0].max() + v[:, 0].min()) < 0.01 * skull.diagonal


def test_at_least_31_landmarks_each_on_its_bone(skull):
    assert len(skull.landmarks) >= 31
    tol = 1e-6 * skull.diagonal
    for bone in ("cranium", "mandible"):
        keys = [k for k, b in skull.bones.items() if b == bone]
        assert keys, bone
        m = trimesh.Trimesh(*getattr(skull, bone), process=False)
        _, d, _ = trimesh.proximity.closest_point(m, np.array([skull.landmarks[k] for k in keys]))
        assert d.max() < tol, f"{keys[int(np.argmax(d))]} is {d.max():.2e} off the {bone}"


def test_bones_of_named_landmarks(skull):
    b = skull.bones
    for k in ("2.1", "2.10", "2.13", "2.14", "2.3", "8.2"):
        assert b[k] == "mandible", k
    for k in ("2.2", "8.1", "4.1", "4.2", "3.7", "5.3", "9.15", "11.1"):
        assert b[k] == "cranium", k


def test_left_right_landmarks_are_mirror_images(skull):
    lm = skull.landmarks
    left = [k for k, p in lm.items() if p[0] > 1e-3 * skull.diagonal]
    right = [k for k, p in lm.items() if p[0] < -1e-3 * skull.diagonal]
    assert len(left) == len(right) >= 10
    for k in left:
        mirrored = lm[k] * [-1.0, 1.0, 1.0]
        other = min(right, key=lambda j: np.linalg.norm(lm[j] - mirrored))
        assert np.linalg.norm(lm[other] - mirrored) < 0.005 * skull.diagonal, (k, other)
        assert skull.bones[other] == skull.bones[k]


def test_landmarks_are_distinct(skull):
    p = np.array(list(skull.landmarks.values()))
    d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(len(p)) * 1e9
    assert d.min() > 0.002 * skull.diagonal, "coincident landmarks would make the RBF fit singular"


@pytest.mark.parametrize("pose", [(0.3, 0.0, 0.0), (0.0, 0.08, 0.0), (0.0, 0.0, 0.5), (0.2, -0.07, 0.3),
                                  (-0.05, 0.1, -0.2)])
def test_jaw_transform_is_rigid(skull, pose):
    t = jaw_transform(skull, *pose)
    r = t[:3, :3]
    assert np.allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(r), 1.0, atol=1e-12)
    assert np.allclose(t[3], [0, 0, 0, 1])
    v = skull.mandible[0][::37]
    w = apply_transform(t, v)
    d0 = np.linalg.norm(v[:, None] - v[None], axis=2)
    d1 = np.linalg.norm(w[:, None] - w[None], axis=2)
    assert np.allclose(d0, d1, atol=1e-9 * skull.diagonal)


def test_zero_pose_is_identity(skull):
    assert np.array_equal(jaw_transform(skull, 0.0, 0.0, 0.0), np.eye(4))
    assert np.allclose(posed_mandible(skull), skull.mandible[0])


def test_pitch_rotates_about_the_condyle_axis(skull):
    t = jaw_transform(skull, 0.3, 0.0, 0.0)
    cond = skull.jaw.condyles
    assert np.allclose(apply_transform(t, cond), cond, atol=1e-9 * skull.diagonal)
    # the rotation axis of the pitch is the pitch direction, the angle is the pitch
    w, vecs = np.linalg.eig(t[:3, :3])
    axis = np.real(vecs[:, np.argmin(np.abs(w - 1.0))])
    assert abs(abs(axis @ skull.jaw.pitch_dir) - 1.0) < 1e-9
    assert np.isclose(np.arccos((np.trace(t[:3, :3]) - 1) / 2), 0.3)


def test_three_dofs_compose_in_order(skull):
    j = skull.jaw
    expected = rotation_about_axis(j.yaw_point, j.yaw_dir, 0.05) @ rotation_about_axis(j.pitch_point, j.pitch_dir, 0.2)
    expected[:3, 3] += 0.4 * j.protrusion_dir
    assert np.allclose(jaw_transform(skull, 0.2, 0.05, 0.4), expected)


def test_protrusion_is_a_forward_translation(skull):
    t = jaw_transform(skull, 0.0, 0.0, 0.5)
    assert np.allclose(t[:3, :3], np.eye(3))
    assert np.isclose(np.linalg.norm(t[:3, 3]), 0.5)
    assert t[2, 3] > 0.4, "forward is +Z"
    assert abs(t[0, 3]) < 1e-12, "protrusion stays in the midsagittal plane"


def test_opening_lowers_the_chin_and_moves_only_mandible_landmarks(skull):
    rest = skull.landmarks
    opened = posed_landmarks(skull, 0.3, 0.0, 0.0)
    drop = rest["2.1"][1] - opened["2.1"][1]
    assert drop > 1.5, f"chin dropped only {drop:.2f} cm for 0.3 rad"
    for k, bone in skull.bones.items():
        moved = np.linalg.norm(opened[k] - rest[k])
        if bone == "mandible":
            assert moved > 0.1, k
        else:
            assert moved == 0.0, k


def test_yaw_turns_the_chin_to_the_subjects_left(skull):
    moved = posed_landmarks(skull, 0.0, 0.08, 0.0)
    assert moved["2.10"][0] > 0.3


def test_jaw_limits_contain_rest_and_clamp(skull):
    lim = skull.jaw.limits
    assert lim["pitch"][0] <= 0 < 0.3 <= lim["pitch"][1]
    assert skull.jaw.clamp(9.0, -9.0, 0.0) == (lim["pitch"][1], lim["yaw"][0], 0.0)


def test_jaw_axes_orthonormal_and_oriented(skull):
    j = skull.jaw
    assert j.pitch_dir[0] > 0.99, "pitch axis runs left-right (+X = subject's left)"
    assert j.yaw_dir[1] > 0.9, "yaw axis is (nearly) vertical"
    assert j.protrusion_dir[2] > 0.9, "protrusion is forward"
    m = np.stack([j.pitch_dir, j.yaw_dir, j.protrusion_dir])
    assert np.allclose(m @ m.T, np.eye(3), atol=1e-5)
    # the condyles are behind and above the chin, on the mandible's upper end
    mv = skull.mandible[0]
    for c in j.condyles:
        assert np.linalg.norm(mv - c, axis=1).min() < 0.05 * skull.diagonal
        assert c[2] < skull.landmarks["2.10"][2] - 5.0


# --------------------------------------------------------------------------- validation
def _copy(tmp_path):
    dst = tmp_path / "skull"
    shutil.copytree(SKULL, dst)
    return dst


def test_missing_mesh_names_the_file(tmp_path):
    d = _copy(tmp_path)
    (d / "mandible.obj").unlink()
    with pytest.raises(TemplateError, match="mandible.obj"):
        load_skull(d)


def test_bad_bone_names_file_and_landmark(tmp_path):
    d = _copy(tmp_path)
    p = d / "landmarks.yaml"
    p.write_text(p.read_text().replace('"2.10": {position:', '"2.10": {bone: jaw, position:', 1)
                 .replace("bone: mandible}  # chin boss", "}  # chin boss", 1))
    with pytest.raises(TemplateError, match=r"landmarks.yaml.*2\.10.*bone"):
        load_skull(d)


def test_landmark_off_its_bone_is_rejected(tmp_path):
    d = _copy(tmp_path)
    p = d / "landmarks.yaml"
    text = p.read_text()
    # claim the chin lies on the cranium
    text = text.replace("bone: mandible}  # chin boss", "bone: cranium}  # chin boss", 1)
    p.write_text(text)
    with pytest.raises(TemplateError, match=r"landmarks.yaml.*2\.10.*cranium"):
        load_skull(d)


def test_condyle_off_the_pitch_axis_is_rejected(tmp_path):
    d = _copy(tmp_path)
    p = d / "jaw.yaml"
    text = p.read_text().replace("direction: [1.0, 0.0, 0.0]", "direction: [1.0, 0.3, 0.0]", 1)
    p.write_text(text)
    with pytest.raises(TemplateError, match=r"jaw.yaml.*condyle"):
        load_skull(d)


def test_malformed_yaml_names_file_and_line(tmp_path):
    d = _copy(tmp_path)
    (d / "jaw.yaml").write_text("units: cm\npitch_axis: {point: [0, 1\n")
    with pytest.raises(TemplateError, match=r"jaw.yaml:\d+"):
        load_skull(d)


def test_condylar_glide_moves_the_chin_down_rather_than_back(skull):
    """Turning about the condyles alone swings the template's chin back as far as down; with
    the condyles gliding forward and down the eminence the chin mostly drops."""
    from dataclasses import replace

    from faceforge.anatomy.skull import condylar_glide

    j = skull.jaw
    chin = skull.landmarks["2.1"][None]
    lever = float(np.linalg.norm((chin[0] - j.pitch_point)[1:]))
    glide = condylar_glide(j.protrusion_dir, j.pitch_dir, lever, 0.6, 35.0)
    assert np.isclose(np.linalg.norm(glide), 0.6 * lever)
    assert glide[2] > 0 and glide[1] < 0 and abs(glide[0]) < 1e-9, "forward and down, in the midplane"
    glided = replace(skull, jaw=replace(j, glide=glide))
    turn = apply_transform(jaw_transform(skull, 0.3, 0.0, 0.0), chin)[0] - chin[0]
    slide = apply_transform(jaw_transform(glided, 0.3, 0.0, 0.0), chin)[0] - chin[0]
    assert -turn[2] > 0.8 * -turn[1], "a pure turn: back about as far as down"
    assert -slide[2] < 0.34 * -slide[1], "with the glide: back at most a third of the way down"
    # closing past rest and the zero pose: no glide
    assert np.array_equal(jaw_transform(glided, 0.0, 0.0, 0.0), np.eye(4))
    assert np.allclose(jaw_transform(glided, -0.02, 0.0, 0.0), jaw_transform(skull, -0.02, 0.0, 0.0))


@pytest.mark.parametrize("drop", [0.8, 1.0, 1.3])
@pytest.mark.parametrize("back_per_down", [0.2, 0.33])
def test_chin_path_ratio_gives_every_chin_the_same_path(skull, drop, back_per_down):
    """The glide fraction solved for a chin lower or higher below the condyles puts that chin on
    the asked path at the solve's opening (10 degrees), where one fixed fraction does not."""
    from dataclasses import replace

    from faceforge.anatomy.skull import chin_path_ratio, condylar_glide

    j = skull.jaw
    chin = skull.landmarks["2.1"].copy()
    chin[1] = j.pitch_point[1] + drop * (chin[1] - j.pitch_point[1])     # a longer or shorter chin
    ratio = chin_path_ratio(chin, j.pitch_point, j.pitch_dir, j.protrusion_dir, 35.0, back_per_down)
    assert 0.0 < ratio < 2.0
    lever = float(np.linalg.norm(np.cross(chin - j.pitch_point, j.pitch_dir)))
    glided = replace(skull, jaw=replace(j, glide=condylar_glide(j.protrusion_dir, j.pitch_dir, lever, ratio, 35.0)))
    d = apply_transform(jaw_transform(glided, np.radians(10.0), 0.0, 0.0), chin[None])[0] - chin
    assert -d[1] > 0 and np.isclose(-d[2] / -d[1], back_per_down, atol=1e-9)


def test_chin_path_ratio_is_clipped_to_the_glide_range(skull):
    """A path no glide in [0, 2] reaches (the chin going forward as it drops) takes the bound."""
    from faceforge.anatomy.skull import chin_path_ratio

    j = skull.jaw
    chin = skull.landmarks["2.1"]
    assert chin_path_ratio(chin, j.pitch_point, j.pitch_dir, j.protrusion_dir, 35.0, 1.5) == 0.0
    assert chin_path_ratio(chin, j.pitch_point, j.pitch_dir, j.protrusion_dir, 35.0, -1.0) == 2.0
