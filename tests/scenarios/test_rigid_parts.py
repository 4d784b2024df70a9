"""A head with eyeballs and teeth in its mesh (faceforge.skin.parts, the rig's parts step): through
fit, bind and animate the eyeballs and the upper teeth stay on the cranium and the lower teeth
ride the jaw, rigidly, while the lids close and the jaw opens; the left eyeball turns with its
yaw FAP (23)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import trimesh
import yaml

from tests.reliability.conftest import cli_run

MEDIAPIPE = Path(__file__).resolve().parents[2] / "samples" / "mediapipe"


def _with_parts(folder: Path) -> tuple[Path, dict]:
    """The MediaPipe face with two eyeballs, two rows of teeth and a lash card appended (its
    landmark file still fits: the face's vertex ids come first). Returns the OBJ and the ids of
    each added piece."""
    face = trimesh.load(MEDIAPIPE / "face_model_with_iris.obj", process=False)
    lm = yaml.safe_load((MEDIAPIPE / "face_model_with_iris.fdp.yaml").read_text())["landmarks"]

    def p(k):
        return np.array(lm[k]["position"], dtype=float)

    mw = np.linalg.norm(p("8.3") - p("8.4"))
    mouth = 0.5 * (p("2.2") + p("2.3"))
    pieces = {}
    for name, (a, b) in (("eye_l", ("3.7", "3.11")), ("eye_r", ("3.8", "3.12"))):
        r = 0.4 * np.linalg.norm(p(a) - p(b))
        pieces[name] = trimesh.creation.icosphere(subdivisions=2, radius=r)
        pieces[name].apply_translation(0.5 * (p(a) + p(b)) - [0.0, 0.0, 1.2 * r])
    for name, dy in (("upper_teeth", 0.12), ("lower_teeth", -0.12)):
        pieces[name] = trimesh.creation.box(extents=[0.6 * mw, 0.15 * mw, 0.1 * mw])
        pieces[name].apply_translation(mouth + [0.0, dy * mw, -0.35 * mw])
    pieces["lash"] = trimesh.creation.box(extents=[0.3 * mw, 0.02 * mw, 0.005 * mw])
    pieces["lash"].apply_translation(p("3.1") + [0.0, 0.01 * mw, 0.06 * mw])
    v, f, ids, n = [np.asarray(face.vertices)], [np.asarray(face.faces)], {}, len(face.vertices)
    for name, piece in pieces.items():
        ids[name] = np.arange(n, n + len(piece.vertices))
        v.append(np.asarray(piece.vertices))
        f.append(np.asarray(piece.faces) + n)
        n += len(piece.vertices)
    path = folder / "parts.obj"
    path.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in np.concatenate(v))
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.concatenate(f)))
    shutil.copyfile(MEDIAPIPE / "face_model_with_iris.fdp.yaml", folder / "parts.fdp.yaml")
    return path, ids


def test_eyeballs_and_teeth_ride_their_bones_rigidly(tmp_path):
    mesh, ids = _with_parts(tmp_path)
    w = tmp_path / "w"
    assert cli_run("-w", w, "fit", mesh).exit_code == 0
    r = cli_run("-w", w, "bind")
    assert r.exit_code == 0, r.stderr
    assert "rigid pieces (eyeballs, teeth): 332 vertices ride the cranium, 8 the mandible" in r.stderr
    bits = ["0"] * 68
    for fap in (3, 19, 20, 23):                            # open_jaw, close_t_l/r_eyelid, yaw_l_eyeball
        bits[fap - 1] = "1"
    fap = tmp_path / "jaw_blink.fap"
    fap.write_text("2.1 jaw 25 6\n" + "".join(f"{' '.join(bits)}\n{i} {i * 200} {i * 200} {i * 200} {i * 8000}\n"
                                              for i in range(6)))
    r = cli_run("-w", w, "--set", "animate.calibrate.enabled=false", "animate", "--fap", fap,
                "-o", tmp_path / "out.pc2")
    assert r.exit_code == 0, r.stderr
    assert "eyeballs (FAPs 23-26) on 2 eyeball pieces" in r.stderr
    from faceforge.io.export_cache import read_pc2

    frames = np.asarray(read_pc2(tmp_path / "out.pc2")[0], dtype=float)
    rest, last = frames[0], frames[-1]
    for name in ("eye_r", "upper_teeth"):                  # the head does not turn: on the cranium, still
        assert np.abs(frames[:, ids[name]] - rest[ids[name]]).max() < 1e-5, name
    teeth = ids["lower_teeth"]
    a, b = rest[teeth], last[teeth]
    pairs = np.linalg.norm(a[:, None] - a[None], axis=2), np.linalg.norm(b[:, None] - b[None], axis=2)
    assert np.abs(pairs[0] - pairs[1]).max() < 1e-4        # rigid (float32 frames)
    assert (b - a)[:, 1].mean() < -0.5                      # down with the jaw (cm)
    eye = ids["eye_l"]                                     # turned 0.4 rad to the left, rigidly
    a, b = rest[eye], last[eye]
    pairs = np.linalg.norm(a[:, None] - a[None], axis=2), np.linalg.norm(b[:, None] - b[None], axis=2)
    assert np.abs(pairs[0] - pairs[1]).max() < 1e-4
    front = np.argmax(a[:, 2])                             # its front moves to the subject's left (+X)
    assert b[front, 0] - a[front, 0] > 0.2
    # the skin did move: the lids closed over the (still) eyeballs
    assert np.abs(last[:468] - rest[:468]).max() > 0.3


def test_held_poses_put_the_pieces_on_their_bones_too(tmp_path):
    """The settled poses (expressions, visemes, calibration, the bake) finish their frames as
    playback does (animation.playback.finish_frame): the eyeballs stay, the lower teeth open with
    the jaw, rigidly."""
    from faceforge.animation.rig import BoundHead
    from faceforge.animation.statics import SettleSettings, settle
    from faceforge.io.config import load_config

    mesh, ids = _with_parts(tmp_path)
    w = tmp_path / "w"
    assert cli_run("-w", w, "fit", mesh).exit_code == 0
    assert cli_run("-w", w, "bind").exit_code == 0
    head = BoundHead(w / "fit", w / "bind", load_config())
    c = np.zeros((1, len(head.controls)))
    poses = settle(head.rig, c, np.array([[0.2, 0.0, 0.0]]), 25.0, SettleSettings(max_frames=40))
    rest = head.rest
    for name in ("eye_l", "eye_r", "upper_teeth"):
        assert np.abs(poses[0, ids[name]] - rest[ids[name]]).max() < 1e-12, name
    t = head.skull.jaw_transform(0.2, 0.0, 0.0)
    teeth = rest[ids["lower_teeth"]] @ t[:3, :3].T + t[:3, 3]
    assert np.abs(poses[0, ids["lower_teeth"]] - teeth).max() < 1e-12
    # the held poses' checks (expressions, visemes, the bake's shapes) do not count them inside the bones
    exempt = head.inside_at_rest()
    assert all(exempt[ids[name]].all() for name in ("eye_l", "eye_r", "upper_teeth", "lower_teeth"))
    assert not exempt[ids["lash"]].any()
