"""fit.simulation_vertices: a head with more vertices than the key is fitted, bound and simulated on a
decimated copy, and every written frame is the user's mesh (its vertex count and order)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from faceforge.fit.proxy import landmarks_by_position, needs_proxy
from faceforge.geometry.embed import working_corners

ROOT = Path(__file__).resolve().parents[2]
MEDIAPIPE = ROOT / "samples" / "mediapipe" / "face_model_with_iris.obj"


def test_the_threshold_and_zero_for_never():
    assert not needs_proxy(45_000, 0)
    assert not needs_proxy(20_000, 20_000)
    assert needs_proxy(20_001, 20_000)


def test_the_lip_cut_copies_carry_the_lower_lip():
    fit_faces = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
    # bind copied vertex 2 (-> 5) and rewired the lower triangle [2, 3, 4] to it; removed none
    working = np.array([[0, 1, 2], [1, 3, 2], [5, 3, 4]])
    out = working_corners(fit_faces, working, 5, [2])
    np.testing.assert_array_equal(out, working)
    np.testing.assert_array_equal(working_corners(fit_faces, fit_faces, 5, []), fit_faces)


def test_landmark_vertex_ids_become_their_places():
    from faceforge.io.landmarks import RawLandmarks

    uv = np.array([[0.0, 0, 0], [1, 2, 3], [4, 5, 6]])
    raw = RawLandmarks("x", ("2.1", "9.3"), np.array([1, -1]), np.array([[np.nan] * 3, [7.0, 8, 9]]))
    out = landmarks_by_position(raw, uv)
    np.testing.assert_array_equal(out.vertex, [-1, -1])
    np.testing.assert_array_equal(out.position, [[1, 2, 3], [7, 8, 9]])


@pytest.fixture(scope="module")
def proxy_workdir(tmp_path_factory):
    """MediaPipe's head (478 vertices) fitted and bound on a copy of about 350."""
    from click.testing import CliRunner

    from faceforge.cli import cli

    folder = tmp_path_factory.mktemp("proxy")
    shutil.copy(MEDIAPIPE, folder / MEDIAPIPE.name)
    shutil.copy(MEDIAPIPE.with_suffix(".fdp.yaml"), folder / "face_model_with_iris.fdp.yaml")
    work = folder / "w"
    for args in (["fit", str(folder / MEDIAPIPE.name)], ["bind"]):
        result = CliRunner().invoke(cli, ["-q", "-w", str(work), "--set", "fit.simulation_vertices=350", *args])
        assert result.exit_code == 0, result.output
    return folder, work


def test_a_head_over_the_threshold_is_simulated_on_a_proxy_and_written_in_the_users_order(proxy_workdir,
                                                                                          short_fap):
    from click.testing import CliRunner

    from faceforge.animation.rig import BoundHead
    from faceforge.cli import cli
    from faceforge.io.config import load_config
    from faceforge.io.frame_stream import open_frames
    from faceforge.io.mesh import load_mesh
    from faceforge.io.stagefiles import load_npz

    folder, work = proxy_workdir
    fit = load_npz(work / "fit" / "fit.npz")
    user, _, _ = load_mesh(folder / MEDIAPIPE.name)
    assert len(fit["skin_vertices"]) < len(user) and len(fit["skin_embed_face"]) == len(user)
    head = BoundHead(work / "fit", work / "bind", load_config())
    diag = float(np.linalg.norm(np.ptp(user, axis=0)))
    # the rest pose carried back is the user's mesh, vertex for vertex
    assert np.abs(head.to_user(head.rest[None])[0] - user).max() < 1e-9 * diag
    out = folder / "joy.pc2"
    result = CliRunner().invoke(cli, ["-q", "-w", str(work), "--set", "fit.simulation_vertices=350", "--set",
                                      "animate.calibrate.enabled=false", "animate", "--fap", str(short_fap),
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    frames = open_frames(work / "animate" / "animation.npz")
    assert frames.shape[1:] == (len(user), 3)
    assert np.abs(np.asarray(frames[0]) - user).max() < 0.05 * diag   # the first frame: near rest, same order
    assert out.stat().st_size > len(user) * 12 * len(frames)
    import json

    checks = json.loads((work / "animate" / "report.json").read_text())["checks"]
    assert "carried" in checks and checks["carried"]["inverted_triangles"] == 0


def test_a_frame_is_carried_once_for_its_check_and_its_output(proxy_workdir, short_fap, monkeypatch):
    """Without a head turn (which comes after the checks: those frames are carried again)."""
    from click.testing import CliRunner

    from faceforge.animation.rig import BoundHead
    from faceforge.cli import cli
    from faceforge.io.frame_stream import open_frames
    from faceforge.mpeg4 import read_fap, write_fap

    folder, work = proxy_workdir
    track = read_fap(short_fap)
    track.mask[:, 47:50] = False   # FAPs 48-50: the head's pitch, yaw, roll
    still = folder / "still.fap"
    write_fap(still, track)
    seen = []
    plain = BoundHead.carried

    def counted(self, frames):
        seen.append(len(frames))
        return plain(self, frames)

    monkeypatch.setattr(BoundHead, "carried", counted)
    result = CliRunner().invoke(cli, ["-q", "-w", str(work), "--set", "fit.simulation_vertices=350", "--set",
                                      "animate.calibrate.enabled=false", "animate", "--fap", str(still),
                                      "--force"])
    assert result.exit_code == 0, result.output
    n = len(open_frames(work / "animate" / "animation.npz"))
    assert sum(seen) == n + 1   # each frame once, and the rest for the check's reference


def test_below_the_threshold_fit_writes_the_same_bytes(tmp_path):
    from click.testing import CliRunner

    from faceforge.cli import cli

    shutil.copy(MEDIAPIPE, tmp_path / MEDIAPIPE.name)
    shutil.copy(MEDIAPIPE.with_suffix(".fdp.yaml"), tmp_path / "face_model_with_iris.fdp.yaml")
    npz = []
    for key in (0, 100_000):
        work = tmp_path / f"w{key}"
        result = CliRunner().invoke(cli, ["-q", "-w", str(work), "--set", f"fit.simulation_vertices={key}", "fit",
                                          str(tmp_path / MEDIAPIPE.name)])
        assert result.exit_code == 0, result.output
        npz.append((work / "fit" / "fit.npz").read_bytes())
    assert npz[0] == npz[1]


def test_the_lip_contours_are_locked_from_corner_to_corner():
    from faceforge.fit.proxy import lip_lock
    from tests.geometry.test_embed import grid

    v, f = grid(11, 10.0)   # 1-unit spacing; the lip line along y = 5
    points = {"2.4": [0.0, 5.0, 0.0], "2.5": [10.0, 5.0, 0.0], "2.2": [5.0, 5.0, 0.0], "2.3": [5.0, 5.0, 0.0]}
    row = np.isclose(v[:, 1], 5.0)
    lock = lip_lock(v, f, points, rings=0)
    np.testing.assert_array_equal(lock, row)
    assert lip_lock(v, f, points, rings=1).sum() > row.sum()
    assert not lip_lock(v, f, {"2.4": [0.0, 5.0, 0.0]}).any()


def slit_grid():
    """``grid(11, 10.0)`` cut along y = 5 between x = 2 and 8 (the lower side's triangles
    rewired to copies of the row's interior vertices, as bind cuts lips): ``(vertices,
    faces, upper, lower)``, the contours corner to corner."""
    from tests.geometry.test_embed import grid

    v, f = grid(11, 10.0)
    row = [int(np.flatnonzero(np.isclose(v[:, 0], x) & np.isclose(v[:, 1], 5.0))[0]) for x in range(2, 9)]
    inner = row[1:-1]
    copies = len(v) + np.arange(len(inner))
    below = v[f].mean(axis=1)[:, 1] < 5.0
    g = f.copy()
    for a, b in zip(inner, copies):
        g[below & (f == a).any(axis=1)] = np.where(g[below & (f == a).any(axis=1)] == a, b, g[below & (f == a).any(axis=1)])
    return np.concatenate([v, v[inner]]), g, np.asarray(row), np.asarray([row[0], *copies, row[-1]])


def test_a_vertex_is_on_the_lip_its_edge_paths_reach_first():
    from faceforge.fit.proxy import lip_sides

    v, f, upper, lower = slit_grid()
    side = lip_sides(v, f, upper, lower)
    at = {tuple(p): s for p, s in zip(v[:len(v) - 5].round(3).tolist(), side.tolist())}
    assert at[(5.0, 7.0, 0.0)] == 1 and at[(5.0, 3.0, 0.0)] == -1      # above / below the slit
    assert at[(0.0, 5.0, 0.0)] == 0                                     # beside the corner: the cheek
    assert at[(5.0, 10.0, 0.0)] == 1                                    # within the mouth's width (6)
    far = lip_sides(v, f, upper, lower, reach=4.0)
    assert far[np.flatnonzero(np.isclose(v[:, 0], 5) & np.isclose(v[:, 1], 10))[0]] == 0   # beyond the reach
    np.testing.assert_array_equal(side[upper[1:-1]], 1)
    np.testing.assert_array_equal(side[lower[1:-1]], -1)
    np.testing.assert_array_equal(side[[upper[0], upper[-1]]], 0)


def test_the_lip_contours_run_corner_to_corner_through_the_fdps():
    from faceforge.fit.proxy import lip_contours
    from tests.geometry.test_embed import grid

    v, f = grid(11, 10.0)
    points = {"2.4": [0.0, 5.0, 0.0], "2.5": [10.0, 5.0, 0.0], "2.2": [5.0, 6.0, 0.0], "2.3": [5.0, 4.0, 0.0]}
    upper, lower = lip_contours(v, f, points)
    assert upper[0] == lower[0] and upper[-1] == lower[-1]
    np.testing.assert_allclose(v[upper[[0, -1]]], [[0, 5, 0], [10, 5, 0]])
    assert (v[upper, 1] >= 5).all() and (v[lower, 1] <= 5).all() and v[upper, 1].max() == 6
    assert lip_contours(v, f, {"2.4": [0.0, 5.0, 0.0]}) is None


def test_the_corner_lock_keeps_the_commissure_whole():
    from faceforge.fit.proxy import lip_lock
    from tests.geometry.test_embed import grid

    v, f = grid(21, 20.0)   # 1-unit spacing; the lip line along y = 10 from x = 5 to 15 (a mouth 10 wide)
    points = {"2.4": [5.0, 10.0, 0.0], "2.5": [15.0, 10.0, 0.0], "2.2": [10.0, 10.0, 0.0], "2.3": [10.0, 10.0, 0.0]}
    plain = lip_lock(v, f, points)
    lock = lip_lock(v, f, points, corner_reach=0.25)   # 2.5 units along the edges from either corner
    assert (lock >= plain).all() and lock.sum() > plain.sum()
    near = np.minimum(np.linalg.norm(v[:, :2] - [5.0, 10.0], axis=1), np.linalg.norm(v[:, :2] - [15.0, 10.0], axis=1))
    assert lock[near <= 1.5].all()                          # the corners' fans, two rings deep
    assert not lock[(near > 3.6) & (np.abs(v[:, 1] - 10) > 1.5)].any()   # nothing beyond the reach but the lip band
    np.testing.assert_array_equal(lip_lock(v, f, points, corner_reach=0.0), plain)


def test_a_proxy_heads_sheet_darkens_the_mouth_on_the_users_own_triangles(proxy_workdir):
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config
    from faceforge.viz.head_sheet import cavity
    from faceforge.viz.smooth import mouth_cavity

    folder, work = proxy_workdir
    head = BoundHead(work / "fit", work / "bind", load_config())
    mm = units_per_mm(head.landmarks)
    user = head.carried(head.rest[None])[0]
    dim = cavity(head, mm, user, head.user_faces)
    assert dim.shape == (len(user),) and dim.max() > 0.5   # the user's mouth inside, dark
    fv, r = head.fdp_vertex, head.rest
    np.testing.assert_array_equal(dim, mouth_cavity(user, head.user_faces, r[fv["2.2"]], r[fv["2.3"]],
                                                    r[[fv["8.3"], fv["8.4"]]], r[[fv["8.1"], fv["8.2"]]], mm))


def test_a_proxy_head_has_no_skin_fold_limit_unless_asked(proxy_workdir):
    """skin.proxy_fold_limit false (the default): a proxy head's skin keeps only the commissure's
    fold limit (the skin's limit threw the locked mouth corner's vertices, docs/notes/dense23.md);
    true: skin.fold_deg on every flat quad as on any head."""
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config

    _, work = proxy_workdir
    off = BoundHead(work / "fit", work / "bind", load_config(sets=["skin.proxy_fold_limit=false"]))._folds
    on = BoundHead(work / "fit", work / "bind", load_config(sets=["skin.proxy_fold_limit=true"]))._folds
    assert on is not None and (off is None or len(off[0]) < len(on[0]) / 10)
