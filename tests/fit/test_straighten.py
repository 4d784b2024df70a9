"""A head turned off the axes in its file (fit.straighten_deg, docs/notes/robust19.md): turned by
its landmarks' frame onto the template's, so it is fitted upright whatever its yaw and pitch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from faceforge.geometry.orientation import angle_between, straightening_rotation

from .heads import SAMPLES


def _turn(yaw_deg, pitch_deg):
    a, b = np.radians(yaw_deg), np.radians(pitch_deg)
    ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return ry @ rx


def test_straightening_rotation_takes_the_frame_onto_the_reference():
    q = _turn(20, 15)
    ref = _turn(0, -7)
    up, fw = q @ [0, 1, 0], q @ [0, 0, 1]
    r = straightening_rotation(up, fw, ref @ [0, 1, 0], ref @ [0, 0, 1])
    assert np.allclose(r @ up, ref @ [0, 1, 0]) and np.allclose(r @ fw, ref @ [0, 0, 1])
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(r, ref @ q.T)


@pytest.fixture(scope="module")
def makehuman():
    from faceforge.io.landmarks import points_frame, read_landmarks
    from faceforge.io.mesh import load_mesh
    from faceforge.io.stagefiles import load_yaml

    mesh = SAMPLES["makehuman"]
    v, _, _ = load_mesh(mesh)
    raw = read_landmarks(mesh.with_name(mesh.stem + ".fdp.yaml"))
    raw = dataclasses.replace(raw, orientation=None)          # the frame told by the landmarks alone
    skull = load_yaml(SAMPLES["makehuman"].parents[2] / "templates/skull/landmarks.yaml")["landmarks"]
    reference = points_frame({k: np.asarray(e["position"], float) for k, e in skull.items()})
    return v, raw, reference


@pytest.mark.parametrize("yaw, pitch", [(20, 15), (-25, 0), (0, -20), (15, 20)])
def test_a_turned_head_is_fitted_upright(makehuman, yaw, pitch):
    from faceforge.fit.orientation import head_orientation

    v, raw, reference = makehuman
    q = _turn(yaw, pitch)
    turned = v @ q.T
    raw_t = dataclasses.replace(raw, position=raw.position @ q.T)    # the file's positions turn with the mesh
    upright = head_orientation("auto", raw, v, reference, 8.0)
    assert upright.identity and upright.straightened_deg is None      # the sample lies 3.7 deg off the template
    o = head_orientation("auto", raw_t, turned, reference, 8.0)
    assert o.straightened_deg is not None and o.straightened_deg > 8.0
    # the turned head is brought back to within the sample's own few degrees of the template's frame
    back = o.rotation @ q
    assert angle_between(back @ [0, 1, 0], [0, 1, 0]) < 5.0 and angle_between(back @ [0, 0, 1], [0, 0, 1]) < 5.0
    assert abs(back[0] @ [1, 0, 0] - 1.0) < 1e-6                      # the left-right axis exactly: yaw and roll gone
    assert o.as_dict()["straightened_deg"] == pytest.approx(o.straightened_deg, abs=1e-3)
    off = head_orientation("auto", raw_t, turned, reference, None)      # fit.straighten_deg 0: snapped to the axes only
    assert off.identity and off.tilt_deg > 14.0


def test_a_declared_frame_is_not_straightened(makehuman):
    from faceforge.fit.orientation import head_orientation

    v, raw, reference = makehuman
    q = _turn(20, 0)
    o = head_orientation("+Y,+Z", dataclasses.replace(raw, position=raw.position @ q.T), v @ q.T, reference, 8.0)
    assert o.identity and o.straightened_deg is None


def test_the_usd_up_axis_of_a_straightened_z_up_head_is_z():
    from faceforge.geometry.orientation import frame_rotation
    from faceforge.io.export_usd import up_axis_of

    r = _turn(10, 12) @ frame_rotation([0, 0, 1], [0, -1, 0])
    assert up_axis_of(r) == "Z" and up_axis_of(_turn(10, 12)) == "Y"
