"""USD export: text (.usda, written by faceforge) and binary (.usdc, through usd-core), both
read back by Pixar's own reader (usd-core, an independent implementation)."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.io.export import ExportError, check_output, export_animation, read_usd, up_axis_of, write_usda
from faceforge.io.export_common import faces_to_csr

from tests.io.test_export import animation

pytest.importorskip("pxr", reason="usd-core is in the test extra")


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd"])
def test_usd_round_trip_is_exact_with_the_user_polygons(tmp_path, suffix):
    frames, faces = animation(n_frames=7)
    frames = frames * 1e3 + 1e-3           # values that need every one of float32's digits
    out = export_animation(tmp_path / f"a{suffix}", frames, faces, 24.0)
    got, fps, counts, indices, up = read_usd(out)
    assert np.array_equal(got, frames.astype(np.float32))
    assert fps == 24.0 and up == "Y"
    idx, starts = faces_to_csr(faces, frames.shape[1])
    assert counts == np.diff(starts).tolist() and indices == idx.tolist()


def test_usd_stage_metadata_and_extent(tmp_path):
    from pxr import Usd, UsdGeom

    frames, faces = animation(n_frames=3)
    write_usda(tmp_path / "a.usda", frames, faces, 30.0, up_axis="Z")
    stage = Usd.Stage.Open(str(tmp_path / "a.usda"))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 2)
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and stage.GetDefaultPrim().GetName() == "faceforge"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/faceforge/head"))
    for k in range(3):
        lo, hi = np.asarray(mesh.GetExtentAttr().Get(k))
        f = frames[k].astype(np.float32)
        assert np.array_equal(lo, f.min(0)) and np.array_equal(hi, f.max(0))
    # the time samples are the frames, and their interpolation between frames is linear
    mid = np.asarray(mesh.GetPointsAttr().Get(0.5))
    assert np.allclose(mid, 0.5 * (frames[0] + frames[1]), atol=1e-5)


def test_usd_needs_faces_and_a_usd_up_axis(tmp_path):
    frames, faces = animation(n_frames=2)
    with pytest.raises(ExportError, match="needs its faces"):
        write_usda(tmp_path / "a.usda", frames, None, 25.0)
    with pytest.raises(ExportError, match="'Y' or 'Z'"):
        write_usda(tmp_path / "a.usda", frames, faces, 25.0, up_axis="X")
    assert not (tmp_path / "a.usda").exists()


def test_up_axis_of_the_users_frame():
    from faceforge.geometry.orientation import frame_rotation, parse_axis

    assert up_axis_of(np.eye(3)) == "Y"
    assert up_axis_of(frame_rotation(parse_axis("+Z"), parse_axis("-Y"))) == "Z"


def test_binary_usd_without_usd_core_fails_before_simulating(monkeypatch, tmp_path):
    import faceforge.io.export_usd as usd

    monkeypatch.setattr(usd, "_pxr", lambda: None)
    with pytest.raises(ExportError, match="pip install usd-core"):
        check_output(tmp_path / "a.usdc")
    check_output(tmp_path / "a.usda")          # text USD needs nothing
