"""FDP landmark files: formats, snapping, and every validation error."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from faceforge.exceptions import FaceforgeError, LandmarkError
from faceforge.io.landmarks import (REQUIRED_FDPS, default_landmark_path,
                                    load_landmarks, read_landmarks, snap_landmarks)
from faceforge.mpeg4 import FDP_IDS, LEFT_RIGHT_PAIRS

from tests.fit.heads import SAMPLES, face_landmarks_on


@pytest.fixture()
def head(ellipsoid):
    v, f = ellipsoid
    return v, f, face_landmarks_on(v, f)


def write_yaml(path, pts, vertex=None):
    vertex = vertex or {}
    data = {"landmarks": {k: {"vertex": vertex.get(k), "position": [float(c) for c in p]} for k, p in pts.items()}}
    path.write_text(yaml.safe_dump(data))
    return path


def test_fdp_table_is_the_standard():
    assert len(FDP_IDS) == 84 and len(set(FDP_IDS)) == 84
    flat = [f for p in LEFT_RIGHT_PAIRS for f in p]
    assert len(flat) == len(set(flat)) and set(flat) <= set(FDP_IDS)


def test_three_formats_agree_and_snap_onto_the_surface(tmp_path, head):
    v, f, pts = head
    rng = np.random.default_rng(0)
    off = {k: p * (1 + 0.01 * rng.standard_normal()) for k, p in pts.items()}   # slightly off the surface
    y = write_yaml(tmp_path / "a.yaml", off)
    (tmp_path / "a.json").write_text(json.dumps({k: {"vertex": None, "position": list(map(float, p))} for k, p in off.items()}))
    (tmp_path / "a.csv").write_text("fdp,vertex,x,y,z\n" + "".join(f"{k},,{p[0]},{p[1]},{p[2]}\n" for k, p in off.items()))
    results = [load_landmarks(tmp_path / n, v, f) for n in ("a.yaml", "a.json", "a.csv")]
    for r in results[1:]:
        assert set(r.ids) == set(results[0].ids) == set(off)
        for k in r.ids:
            np.testing.assert_allclose(r.positions[r.index(k)], results[0].positions[results[0].index(k)], atol=1e-12)
    r = results[0]
    # the snapped points lie on their triangles: barycentric round trip
    tri = v[f[r.face_ids]]
    np.testing.assert_allclose(np.einsum("ni,nij->nj", r.bary, tri), r.positions, atol=1e-9)
    assert np.all(r.bary > -1e-9)
    assert y.exists()


def test_vertex_id_wins_when_consistent(tmp_path, head):
    v, f, pts = head
    i = int(np.argmax(v[:, 2]))
    pts = dict(pts)
    pts["9.3"] = v[i] + 1e-4  # consistent with vertex i
    lm = load_landmarks(write_yaml(tmp_path / "a.yaml", pts, {"9.3": i}), v, f)
    k = lm.index("9.3")
    assert lm.vertex[k] == i
    np.testing.assert_array_equal(lm.positions[k], v[i])


def test_inconsistent_vertex_and_position(tmp_path, head):
    v, f, pts = head
    pts = dict(pts)
    with pytest.raises(LandmarkError, match=r"9\.3.*vertex 0"):
        load_landmarks(write_yaml(tmp_path / "a.yaml", pts, {"9.3": 0}), v, f)


def test_missing_required(tmp_path, head):
    v, f, pts = head
    pts = {k: p for k, p in pts.items() if k not in ("9.3", "2.1")}
    with pytest.raises(LandmarkError, match=r"required FDP 2\.1, 9\.3 missing") as e:
        load_landmarks(write_yaml(tmp_path / "a.yaml", pts), v, f)
    assert "a.yaml" in str(e.value)


def test_duplicates_in_each_format(tmp_path, head):
    v, f, pts = head
    (tmp_path / "d.yaml").write_text('landmarks:\n  "2.1": {vertex: 1}\n  "2.1": {vertex: 2}\n')
    (tmp_path / "d.json").write_text('{"2.1": {"vertex": 1}, "2.1": {"vertex": 2}}')
    (tmp_path / "d.csv").write_text("fdp,vertex,x,y,z\n2.1,1,,,\n2.1,2,,,\n")
    for name in ("d.yaml", "d.json", "d.csv"):
        with pytest.raises(LandmarkError, match=r"2\.1 given twice"):
            read_landmarks(tmp_path / name)


def test_unknown_and_unquoted_ids(tmp_path):
    (tmp_path / "u.yaml").write_text('landmarks:\n  "2.1": {vertex: 1}\n  "12.3": {vertex: 2}\n')
    with pytest.raises(LandmarkError, match=r"unknown FDP id 12\.3"):
        read_landmarks(tmp_path / "u.yaml")
    (tmp_path / "q.yaml").write_text('landmarks:\n  2.10: {vertex: 1}\n')
    with pytest.raises(LandmarkError, match="quoted"):
        read_landmarks(tmp_path / "q.yaml")


def test_vertex_out_of_range(tmp_path, head):
    v, f, pts = head
    (tmp_path / "o.csv").write_text("fdp,vertex,x,y,z\n2.1,99999,,,\n")
    with pytest.raises(LandmarkError, match=r"out of range.*2\.1 \(99999\)"):
        snap_landmarks(read_landmarks(tmp_path / "o.csv"), v, f)


def test_point_far_from_mesh(tmp_path, head):
    v, f, pts = head
    pts = dict(pts)
    pts["9.3"] = pts["9.3"] * 3.0
    with pytest.raises(LandmarkError, match=r"9\.3 .*far from the mesh"):
        load_landmarks(write_yaml(tmp_path / "a.yaml", pts), v, f)


def test_left_right_swapped(tmp_path, head):
    v, f, pts = head
    pts = dict(pts)
    for l, r in (("3.7", "3.12"), ("3.11", "3.8"), ("4.3", "4.4"), ("8.3", "8.4")):
        pts[l], pts[r] = pts[r], pts[l]
    with pytest.raises(LandmarkError, match=r"left and right swapped.*3\.7"):
        load_landmarks(write_yaml(tmp_path / "a.yaml", pts), v, f)
    mirrored = {k: p * [-1, 1, 1] for k, p in head[2].items()}   # a mirrored head, labels kept
    with pytest.raises(LandmarkError, match="left and right swapped"):
        load_landmarks(write_yaml(tmp_path / "b.yaml", mirrored), v * [-1, 1, 1], f[:, ::-1])


def test_head_facing_backwards(tmp_path, head):
    v, f, pts = head
    rot = np.diag([-1.0, 1.0, -1.0])  # turned 180 degrees about Y: left stays subject-left, now at -X
    turned = {k: p @ rot.T for k, p in pts.items()}
    with pytest.raises(LandmarkError, match="(wrong way|swapped)"):
        load_landmarks(write_yaml(tmp_path / "a.yaml", turned), v @ rot.T, f)
    # only the nose pushed behind the eyes: the facing check names 9.3
    flat = dict(pts)
    flat["9.3"] = flat["9.3"] * [1, 1, -1]
    with pytest.raises(LandmarkError, match=r"wrong way: nose tip 9\.3"):
        load_landmarks(write_yaml(tmp_path / "c.yaml", flat), v, f)


def test_coincident_landmarks(tmp_path, head):
    v, f, pts = head
    pts = dict(pts)
    pts["9.15"] = pts["9.3"]
    with pytest.raises(LandmarkError, match=r"same point: 9\.3=9\.15|same point: 9\.15=9\.3"):
        load_landmarks(write_yaml(tmp_path / "a.yaml", pts), v, f)


def test_malformed_files_are_faceforge_errors(tmp_path):
    cases = {"m.yaml": "landmarks: [1, 2", "m.json": "{", "m.csv": "a,b\n1,2\n", "m.txt": "x",
             "n.yaml": 'landmarks:\n  "2.1": {position: [1, 2]}\n'}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(FaceforgeError) as e:
            read_landmarks(tmp_path / name)
        assert name in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(LandmarkError, match="not found"):
        read_landmarks(tmp_path / "absent.yaml")


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_sample_landmark_files_load(name):
    import trimesh

    mesh = trimesh.load(SAMPLES[name], process=False, force="mesh")
    lm = load_landmarks(default_landmark_path(SAMPLES[name]), mesh.vertices, mesh.faces)
    assert set(REQUIRED_FDPS) <= set(lm.ids)
    given = read_landmarks(default_landmark_path(SAMPLES[name]))
    has_v = given.vertex >= 0
    np.testing.assert_array_equal(lm.positions[has_v], mesh.vertices[given.vertex[has_v]])


def test_vertex_ids_refer_to_the_users_mesh_after_merging(tmp_path, head):
    from faceforge.io.mesh_check import check_mesh

    v, f, pts = head
    soup_v, soup_f = v[f.ravel()], np.arange(3 * len(f)).reshape(-1, 3)   # unwelded: every corner its own vertex
    checked = check_mesh(soup_v, soup_f, "soup.obj")
    ids = {}
    for k, p in pts.items():
        ids[k] = int(np.argmin(np.linalg.norm(soup_v - p, axis=1)))
    y = write_yaml(tmp_path / "a.yaml", {k: soup_v[i] for k, i in ids.items()}, ids)
    lm = load_landmarks(y, checked.vertices, checked.faces, user_to_internal=checked.user_to_internal)
    for k, i in ids.items():
        np.testing.assert_array_equal(lm.positions[lm.index(k)], soup_v[i])
        assert lm.vertex[lm.index(k)] == checked.user_to_internal[i] < len(checked.vertices)
