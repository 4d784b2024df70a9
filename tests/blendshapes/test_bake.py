"""The bake on a stand-in head (linear skin response, known probes) and the CLI's bad input."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.animation.calibrate import Probe
from faceforge.blendshapes.arkit import ShapeSpec
from faceforge.blendshapes.bake import bake_shapes, mirror_agreement
from faceforge.blendshapes.rigsolve import probe_observer
from faceforge.blendshapes.solve import control_space

COLUMNS = ("zyg_L", "zyg_R", "frontalis")


def _head():
    """Six skin vertices, symmetric in x; each control moves one or two of them."""
    rest = np.array([[1, 0, 0], [-1, 0, 0], [0.5, 1, 0], [-0.5, 1, 0], [0, 2, 0], [0, -1, 0]], dtype=float)
    B = np.zeros((4, 6, 3))                       # response per unit control (zyg_L, zyg_R, frontalis, pitch)
    B[0, 0] = (0.1, 0.2, 0)
    B[1, 1] = (-0.1, 0.2, 0)
    B[2, 4] = (0, 0.3, 0)
    B[3, 5] = (0, -1.0, 0)

    def simulate(c, jaw):
        x = np.hstack([c, jaw[:, :1]])
        return rest + np.einsum("kq,qnd->knd", x, B)

    probes = {12: Probe(12, 0, -1, np.array([0.0, 1, 0]), 0.01),    # left corner up, 0.01 a FAPU
              13: Probe(13, 1, -1, np.array([0.0, 1, 0]), 0.01),
              31: Probe(31, 4, -1, np.array([0.0, 1, 0]), 0.01),
              3: Probe(3, 5, -1, np.array([0.0, -1, 0]), 0.01)}
    space = control_space(COLUMNS, set(COLUMNS), {"pitch": (0.0, 0.4)}, pitch_lever=1.0)
    return rest, simulate, probes, space


def test_each_shape_reaches_its_target_with_its_own_controls():
    rest, simulate, probes, space = _head()
    specs = {"smileL": ShapeSpec("smileL", {12: 10.0}, ("zyg_L",)),
             "smileR": ShapeSpec("smileR", {13: 10.0}, ("zyg_R",), mirror_of="smileL"),
             "brow": ShapeSpec("brow", {31: 60.0}, ("frontalis",)),      # needs c = 2: clipped at 1
             "open": ShapeSpec("open", {3: 30.0}, ("jaw.pitch",)),
             "look": ShapeSpec("look", not_made="no eyeballs"),
             "nose": ShapeSpec("nose", {61: 5.0}, ("zyg_L",))}          # FAP 61 has no probe here
    out = bake_shapes(specs, space, probes, simulate, lambda ps: probe_observer(rest, ps), rest, good_enough=0.0)
    assert out.names == ["smileL", "smileR", "brow", "open"]
    assert list(out.report) == list(specs)                                 # every shape reported
    assert out.report["look"] == {"made": False, "reason": "no eyeballs"}
    assert not out.report["nose"]["made"] and "FAP 61" in out.report["nose"]["reason"]
    sl = out.report["smileL"]
    assert sl["error"] < 1e-3 and sl["targets"]["12"]["achieved"] == pytest.approx(10.0, abs=0.05)
    assert out.contractions[0] == pytest.approx([0.5, 0, 0], abs=1e-4)    # only its own muscle
    assert out.contractions[2, 2] == pytest.approx(1.0)                    # the bound holds
    assert out.report["brow"]["error"] == pytest.approx(0.5, abs=1e-3)    # and the miss is reported
    assert out.report["brow"]["reach"] == pytest.approx(0.5, abs=1e-3) and out.report["brow"]["form_error"] < 1e-6
    assert out.report["brow"]["saturated"] == ["frontalis"] and out.report["smileL"]["saturated"] == []
    assert out.jaw[3, 0] == pytest.approx(0.3, abs=1e-4)
    deltas = {n: f - rest for n, f in zip(out.names, out.frames)}
    assert mirror_agreement(rest, deltas, [("smileL", "smileR")]) == {"smileL": 0.0}


def test_bad_arkit_take_is_one_line_exit_2(invoke, tmp_path):
    take = tmp_path / "take.csv"
    take.write_text("Timecode,BlendShapeCount,JawOpen,EyeBlinkLeft\n00:00:00:00.000,2,0.1,0.0\n"
                    "00:00:00:01.000,2,0.2\n")
    result = invoke("--workdir", tmp_path / "w", "animate", "--arkit", take)
    assert result.exit_code == 2
    err = result.stderr.strip()
    assert len(err.splitlines()) == 1 and err.startswith("faceforge: error: ")
    assert f"take.csv:3: 3 fields, the header has 4" in err
    take.write_text("frame,JawOpen,MouthGrin\n0,0.1,0\n")
    result = invoke("--workdir", tmp_path / "w", "animate", "--arkit", take)
    assert result.exit_code == 2 and "take.csv:1: unknown blendshape name 'MouthGrin'" in result.stderr
    take.write_text("frame,JawOpen\n0,1.2\n")
    result = invoke("--workdir", tmp_path / "w", "animate", "--arkit", take)
    assert result.exit_code == 2 and "take.csv:2: jawOpen = 1.2 is outside [0, 1]" in result.stderr


def test_bake_rejects_an_unknown_suffix(invoke, tmp_path):
    result = invoke("--workdir", tmp_path / "w", "bake", "-o", tmp_path / "x.fbx")
    assert result.exit_code == 2 and "bake writes .glb, .usda or .npz" in result.stderr


def test_a_bad_arkit_mapping_fails_before_anything_runs(invoke, tmp_path):
    bad = tmp_path / "map.yaml"
    bad.write_text("shapes:\n  jawOpen: {faps: {3: 100}, controls: [jaw.pitch]}\n")
    result = invoke("--workdir", tmp_path / "w", "bake", "--mapping", bad)
    assert result.exit_code == 2
    assert "map.yaml: shapes: no entry for eyeBlinkLeft, eyeLookDownLeft, eyeLookInLeft and 48 more" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_symmetric_rig_solves_one_side_and_mirrors_the_pose():
    from faceforge.blendshapes.symmetric import mirror_columns

    rest, simulate, probes, space = _head()
    calls = []

    def counted(c, jaw):
        calls.extend(np.asarray(c, dtype=float).copy())
        return simulate(c, jaw)

    specs = {"smileL": ShapeSpec("smileL", {12: 10.0}, ("zyg_L",)),
             "smileR": ShapeSpec("smileR", {13: 10.0}, ("zyg_R",), mirror_of="smileL"),
             "both": ShapeSpec("both", {12: 10.0, 13: 6.0}, ("zyg_L", "zyg_R"))}   # a midline shape
    twins = mirror_columns(COLUMNS)
    assert list(twins) == [1, 0, 2]
    out = bake_shapes(specs, space, probes, counted, lambda ps: probe_observer(rest, ps), rest, twins=twins)
    assert out.report["smileR"]["mirrored_pose"] and "residuals" not in out.report["smileR"]
    assert out.contractions[1] == pytest.approx(out.contractions[0][[1, 0, 2]])    # the twin's column
    assert out.report["smileR"]["error"] < 2e-3                                 # measured on its own FAP
    # the Jacobian has only the controls the solved shapes name (the frontalis is not probed);
    # smileR is settled once, last, at smileL's mirrored pose
    assert [list(np.flatnonzero(p)) for p in calls[:2]] == [[0], [1]]
    assert calls[-1] == pytest.approx(out.contractions[1]) and sum(p[1] > 0 and p[0] == 0 for p in calls[2:]) == 1
    # the midline shape moves both twins together: symmetric, the two targets split evenly (8 each)
    assert out.contractions[2, 0] == pytest.approx(out.contractions[2, 1]) and out.report["both"]["tied"]
    assert out.report["both"]["targets"]["12"]["achieved"] == pytest.approx(8.0, abs=0.05)
    deltas = {n: f - rest for n, f in zip(out.names, out.frames)}
    assert mirror_agreement(rest, deltas, [("smileL", "smileR")]) == {"smileL": 0.0}


def test_a_pose_the_simulation_blew_up_is_not_made():
    # MakeHuman's mirrored mouthSmileRight once settled 1e7 skin units away: no shape, said so
    from faceforge.blendshapes.symmetric import mirror_columns

    rest, simulate, probes, space = _head()

    def unstable(c, jaw):                # the right zygomaticus blows the skin up
        out = simulate(c, jaw)
        out[c[:, 1] > 0] *= 1e6
        return out

    specs = {"smileL": ShapeSpec("smileL", {12: 10.0}, ("zyg_L",)),
             "smileR": ShapeSpec("smileR", {13: 10.0}, ("zyg_R",), mirror_of="smileL")}
    out = bake_shapes(specs, space, probes, unstable, lambda ps: probe_observer(rest, ps), rest,
                      twins=mirror_columns(COLUMNS))
    assert out.names == ["smileL"]
    r = out.report["smileR"]
    assert not r["made"] and "diverged" in r["reason"] and r["controls"]["zyg_R"] == pytest.approx(0.5, abs=1e-3)

    def raising(c, jaw):                 # ... or the settle raises on its non-finite skin
        if np.any(c[:, 1] > 0):
            raise FloatingPointError("pose 0: the simulation produced non-finite skin positions")
        return simulate(c, jaw)

    out = bake_shapes(specs, space, probes, raising, lambda ps: probe_observer(rest, ps), rest,
                      twins=mirror_columns(COLUMNS))
    assert out.names == ["smileL"]
    r = out.report["smileR"]
    assert not r["made"] and "diverged" in r["reason"] and r["controls"]["zyg_R"] == pytest.approx(0.5, abs=1e-3)
    assert out.report["smileL"]["made"]


def test_mirror_pose_swaps_twins_and_negates_the_yaw_only():
    from faceforge.blendshapes.symmetric import mirror_columns, mirror_pose

    cols = ("zygomaticus_major_L", "orbicularis_oris", "zygomaticus_major_R", "risorius_L",
            "orbicularis_oris.protrude")
    twins = mirror_columns(cols)
    assert list(twins) == [2, 1, 0, 3, 4]                       # risorius_R absent: stays on itself
    c, jaw = mirror_pose(np.array([0.7, 0.2, 0.0, 0.4, 0.3]), np.array([0.1, 0.05, 0.02]), twins)
    assert c.tolist() == [0.0, 0.2, 0.7, 0.4, 0.3] and jaw.tolist() == [0.1, -0.05, 0.02]
    c2, jaw2 = mirror_pose(c, jaw, twins)
    assert c2.tolist() == [0.7, 0.2, 0.0, 0.4, 0.3] and jaw2.tolist() == [0.1, 0.05, 0.02]   # an involution


def _mirrored_head():
    """_head with a settle that records every pose it settles (``calls``), the mirror x -> -x and
    the vertices' exact partners: (rest, simulate, probes, space, counted, calls, mirror, partner)."""
    from faceforge.geometry.mirror import Mirror

    rest, simulate, probes, space = _head()
    calls = []

    def counted(c, jaw):
        calls.extend(np.asarray(c, dtype=float).copy())
        return simulate(c, jaw)

    mirror = Mirror(np.zeros(3), (1.0, 0.0, 0.0))
    return rest, simulate, probes, space, counted, calls, mirror, mirror.exact_partners(rest)


def test_mirror_frame_makes_the_right_shape_without_settling_it():
    # bake.mirror_shapes on a symmetric mesh: smileR is smileL's settled skin reflected onto the
    # vertices' exact partners (x -> -x here); no pose of zyg_R alone is ever settled
    from faceforge.blendshapes.symmetric import mirror_columns

    rest, simulate, probes, space, counted, calls, mirror, partner = _mirrored_head()
    assert list(partner) == [1, 0, 3, 2, 4, 5]
    specs = {"smileL": ShapeSpec("smileL", {12: 10.0}, ("zyg_L",)),
             "smileR": ShapeSpec("smileR", {13: 10.0}, ("zyg_R",), mirror_of="smileL")}
    out = bake_shapes(specs, space, probes, counted, lambda ps: probe_observer(rest, ps), rest,
                      twins=mirror_columns(COLUMNS), mirror_frame=lambda f: mirror(f[partner]))
    row = out.report["smileR"]
    assert row["mirrored_shape"] and row["mirrored_pose"] and row["error"] < 2e-3
    assert out.frames[1] == pytest.approx(mirror(out.frames[0][partner]))
    assert out.contractions[1] == pytest.approx(out.contractions[0][[1, 0, 2]])   # the pose it plays
    assert not any(p[1] > 0 and p[0] == 0 for p in calls)                         # never settled
    # on this symmetric stand-in the mirrored skin is what settling the mirrored pose gives
    assert out.frames[1] == pytest.approx(simulate(out.contractions[1:2], np.zeros((1, 3)))[0])


def test_mirror_frame_mirrors_the_jacobian_probe_of_a_twin():
    # with mirror_frame a midline shape's Jacobian probes zyg_L alone and mirrors it for zyg_R:
    # the same Jacobian (a symmetric stand-in) and the same solve, one settle fewer
    from faceforge.blendshapes.bake import _mirrored_jacobian
    from faceforge.blendshapes.solve import jacobian
    from faceforge.blendshapes.symmetric import mirror_columns

    rest, simulate, probes, space, counted, calls, mirror, partner = _mirrored_head()
    observe = probe_observer(rest, [probes[12], probes[13], probes[31]])
    twins = mirror_columns(COLUMNS)
    J = _mirrored_jacobian(counted, observe, space, twins, lambda f: mirror(f[partner]))
    assert J == pytest.approx(jacobian(simulate, observe, space))
    assert len(calls) == len(space.names) - 1 and not any(p[1] > 0 for p in calls)   # zyg_R never settled
    # a skin that is not symmetric gives a different column: the mirror is really used
    skew = _mirrored_jacobian(simulate, observe, space, twins, lambda f: mirror(f[partner]) * 1.5)
    assert not np.allclose(skew, J)
    specs = {"both": ShapeSpec("both", {12: 10.0, 13: 6.0}, ("zyg_L", "zyg_R"))}
    out = bake_shapes(specs, space, probes, simulate, lambda ps: probe_observer(rest, ps), rest, twins=twins,
                      mirror_frame=lambda f: mirror(f[partner]))
    assert out.report["both"]["targets"]["12"]["achieved"] == pytest.approx(8.0, abs=0.05)


def _warm_off_skin():
    """_head's skin answering c^2 (the secant Jacobian overshoots: the solve refines, warm), whose
    warm settles leave the corner 0.05 too high: (rest, cold simulate with ``.warm``, probes, space)."""
    rest, simulate, probes, space = _head()

    def cold(c, jaw):
        return simulate(np.asarray(c) ** 2, jaw)

    def warm(c, jaw):
        out = cold(c, jaw)
        out[:, 0, 1] += 0.05
        return out

    cold.warm = warm
    return rest, cold, probes, space


def test_a_folded_warm_result_is_settled_again_from_rest():
    # a skin answering c^2 (the secant Jacobian overshoots: the solve refines, warm) whose warm
    # settles leave the corner 0.05 too high, counted as a fold: the shape is its pose settled
    # from rest instead, said so in the report; without ``folds`` nothing is settled again
    rest, cold, probes, space = _warm_off_skin()
    specs = {"smileL": ShapeSpec("smileL", {12: 10.0}, ("zyg_L",))}
    observe = lambda ps: probe_observer(rest, ps)                                # noqa: E731
    plain = bake_shapes(specs, space, probes, cold, observe, rest, passes=3)
    assert len(plain.report["smileL"]["residuals"]) > 1 and "settled_from_rest" not in plain.report["smileL"]
    assert plain.frames[0, 0, 1] == pytest.approx(cold(plain.contractions[:1], np.zeros((1, 3)))[0, 0, 1] + 0.05)
    flagged = bake_shapes(specs, space, probes, cold, observe, rest, passes=3,
                          folds=lambda f: int(f[0, 1] - 0.2 * ((f[0, 0] - 1.0) / 0.1) > 1e-9))
    row = flagged.report["smileL"]
    assert row["settled_from_rest"] == {"warm_folds": 1, "folds": 0}
    assert flagged.frames[0] == pytest.approx(cold(flagged.contractions[:1], np.zeros((1, 3)))[0])
    assert row["targets"]["12"]["achieved"] == pytest.approx(
        float(observe([probes[12]])(flagged.frames[:1])[0, 0]), abs=0.05)          # measured on that frame


def test_a_warm_result_stays_when_settling_from_rest_folds_no_less():
    # the same skin, but every frame counts as folded: settling from rest does not help, so the
    # warm frame stays the shape and the report says both counts
    rest, cold, probes, space = _warm_off_skin()
    specs = {"smileL": ShapeSpec("smileL", {12: 10.0}, ("zyg_L",))}
    out = bake_shapes(specs, space, probes, cold, lambda ps: probe_observer(rest, ps), rest, passes=3,
                      folds=lambda f: 2)
    assert out.report["smileL"]["settled_from_rest"] == {"warm_folds": 2, "folds": 2, "cold_folds": 2}
    assert out.frames[0, 0, 1] == pytest.approx(cold(out.contractions[:1], np.zeros((1, 3)))[0, 0, 1] + 0.05)


class _Lids:
    """A stand-in for :class:`faceforge.animation.eyelids.Eyelids`: FAP 19 (upper lid closed, IRISD)
    lowers vertex 4 by 0.001 a unit, FAP 21 raises vertex 5 as much; no jaw hold."""

    jaw_hold = 0.0

    def apply(self, frames, faps, jaw=None):
        out = np.array(frames, dtype=float)
        out[:, 4, 1] -= 0.001 * faps[:, 18]
        out[:, 5, 1] += 0.001 * faps[:, 20]
        return out


def test_a_gaze_with_lids_on_a_head_without_eyeballs_is_its_lids_alone():
    """eyeLookDown on a head without an eyeball piece: the lids follow the gaze (made, said to be an
    approximation); a gaze shape with no lids is not made; with the piece, it turns as well."""
    rest, simulate, probes, space = _head()
    specs = {"down": ShapeSpec("down", lids={19: 400.0, 21: -130.0}, eye={"side": "L", "yaw": 0.0, "pitch": -0.4}),
             "in": ShapeSpec("in", eye={"side": "L", "yaw": -0.5, "pitch": 0.0})}
    out = bake_shapes(specs, space, probes, simulate, lambda ps: probe_observer(rest, ps), rest, lids=_Lids())
    assert out.names == ["down"]
    assert not out.report["in"]["made"] and "no eyeball piece at the L pupil" in out.report["in"]["reason"]
    down = out.report["down"]
    assert down["made"] and "no eyeball turns" in down["approximation"] and down["eye"]["vertices"] == 0
    d = out.frames[0] - rest
    assert d[4, 1] == pytest.approx(-0.4) and d[5, 1] == pytest.approx(-0.13)       # the lids moved, nothing else
    assert np.abs(np.delete(d, [4, 5], axis=0)).max() == 0.0
    assert out.gaze[0] == pytest.approx([0.0, -0.4, 0.0, 0.0])                      # the gaze is still recorded
    turned = bake_shapes(specs, space, probes, simulate, lambda ps: probe_observer(rest, ps), rest, lids=_Lids(),
                         eyes={"L": (np.array([0]), np.array([0.9, 0.0, -0.2]))})
    assert turned.names == ["down", "in"] and turned.report["down"]["approximation"] is None
    assert turned.report["down"]["eye"]["vertices"] == 1 and np.abs(turned.frames[0][0] - rest[0]).max() > 0.01
