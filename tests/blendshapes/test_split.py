"""Left/right ARKit pairs split from their bilateral pose (``bake.split_pairs``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from faceforge.animation.calibrate import Probe
from faceforge.blendshapes.arkit import ShapeSpec
from faceforge.blendshapes.bake import BakedShapes
from faceforge.blendshapes.head import _split, _split_specs
from faceforge.blendshapes.split import (bilateral_controls, bilateral_spec, midline_side, side_weights,
                                         split_controls, split_frame)
from faceforge.exceptions import ConfigError


def test_side_weights_partition_each_mirror_pair_of_vertices():
    s = np.linspace(-3.0, 3.0, 61)
    w = side_weights(s, 1.5)
    assert np.allclose(w + side_weights(-s, 1.5), 1.0)          # a vertex and its mirror image share its motion
    assert w[s <= -1.5].max() == 0.0 and w[s >= 1.5].min() == 1.0
    assert side_weights(np.array([0.0]), 1.5)[0] == 0.5 and np.all(np.diff(w) >= 0.0)


def test_split_controls_add_up_to_the_bilateral_pose_each_side_its_own_muscles():
    sided = np.array([True, True, False])                     # zyg_L, zyg_R, the orbicularis oris
    left_c, right_c = np.array([0.8, 0.0, 0.3]), np.array([0.0, 0.8, 0.3])
    both = bilateral_controls(left_c, right_c, sided)
    assert np.allclose(both, [0.8, 0.8, 0.3])                 # one sphincter: not 0.6
    left, right = split_controls(both, np.array([True, False, False]), np.array([False, True, False]))
    assert np.allclose(left + right, both)
    assert np.allclose(left, [0.8, 0.0, 0.15]) and np.allclose(right, [0.0, 0.8, 0.15])


def test_split_frames_add_up_to_the_bilateral_frame():
    rng = np.random.default_rng(3)
    rest = rng.normal(size=(50, 3))
    bilateral = rest + 0.1 * rng.normal(size=(50, 3))
    w = side_weights(rest[:, 0], 0.5)
    left, right = split_frame(rest, bilateral, w)
    assert np.allclose((left - rest) + (right - rest), bilateral - rest)
    far = rest[:, 0] > 0.5
    assert np.allclose(left[far], bilateral[far]) and np.allclose(right[far], rest[far])


def test_bilateral_spec_takes_both_sides_targets_controls_and_lids():
    left = ShapeSpec("mouthSmileLeft", {12: 100.0, 4: 20.0}, ("zyg_L", "orbicularis_oris"), {21: 50.0})
    right = ShapeSpec("mouthSmileRight", {13: 100.0, 4: -30.0}, ("zyg_R", "orbicularis_oris"), {22: 50.0},
                      mirror_of="mouthSmileLeft")
    b = bilateral_spec("mouthSmile", left, right)
    assert b.name == "mouthSmile" and b.faps == {12: 100.0, 13: 100.0, 4: -30.0}
    assert b.controls == ("zyg_L", "orbicularis_oris", "zyg_R") and b.lids == {21: 50.0, 22: 50.0}


def test_midline_is_halfway_between_the_pupils_positive_on_the_left():
    side = midline_side(np.array([[2.0, 0, 0], [0.0, 5, 1], [-2.0, 0, 0]]), {"3.5": [1.0, 0, 0], "3.6": [-1.0, 0, 0]})
    assert np.allclose(side, [2.0, 0.0, -2.0])
    assert midline_side(np.zeros((1, 3)), {"3.5": [1.0, 0, 0]}) is None


def test_only_splittable_pairs_are_accepted():
    specs = {"jawLeft": ShapeSpec("jawLeft", {}, ("jaw.yaw",)), "jawRight": ShapeSpec("jawRight", {}, ("jaw.yaw",))}
    with pytest.raises(ConfigError, match="bake.split_pairs: jaw"):
        _split_specs(specs, ["jaw"])
    with pytest.raises(ConfigError, match="mouthSmil"):
        _split_specs(specs, ["mouthSmil"])                   # a typo is an error, not silently nothing


def test_a_split_pair_is_its_bilateral_pose_cut_at_the_midline():
    """On a stand-in head: the bilateral frame solved by the bake becomes two shapes whose
    displacements add up to it, each measured against its own side's FAP targets."""
    rest = np.array([[20.0, 0, 0], [-20.0, 0, 0], [0.0, 0, 0], [0.0, 10, 0]])     # mm: the blend is 16 mm wide
    landmarks = {"3.5": np.array([31.5, 20.0, 0]), "3.6": np.array([-31.5, 20.0, 0])}   # ES0 63: units are mm
    head = SimpleNamespace(rest=rest, landmarks=landmarks, controls=("zyg_L", "zyg_R", "orbicularis_oris"))
    bilateral = rest + np.array([[0, 2.0, 0], [0, 2.0, 0], [0, 1.0, 0], [0, 0, 0]])
    baked = BakedShapes(["mouthSmile"], bilateral[None], np.array([[0.9, 0.9, 0.2]]), np.zeros((1, 3)),
                        np.zeros((1, 68)), np.zeros((1, 4)), {"mouthSmile": {"made": True}})
    left = ShapeSpec("mouthSmileLeft", {12: 200.0}, ("zyg_L",))
    right = ShapeSpec("mouthSmileRight", {13: 200.0}, ("zyg_R",), mirror_of="mouthSmileLeft")
    probes = {12: Probe(12, 0, -1, np.array([0.0, 1, 0]), 0.01), 13: Probe(13, 1, -1, np.array([0.0, 1, 0]), 0.01)}
    out = _split(head, {"mouthSmile": (left, right, bilateral_spec("mouthSmile", left, right))}, baked, probes,
                 None, lambda m: None)
    assert out["split"] == ["mouthSmile"]
    i, j = baked.names.index("mouthSmileLeft"), baked.names.index("mouthSmileRight")
    assert np.allclose(baked.frames[i] + baked.frames[j] - 2 * rest, bilateral - rest)
    assert np.allclose(baked.frames[i][0], bilateral[0]) and np.allclose(baked.frames[i][1], rest[1])
    assert np.allclose(baked.contractions[i], [0.9, 0.0, 0.1]) and np.allclose(baked.contractions[j], [0.0, 0.9, 0.1])
    row = baked.report["mouthSmileLeft"]
    assert row["split_from"] == "mouthSmile" and row["targets"]["12"]["achieved"] == 200.0 and row["error"] == 0.0
