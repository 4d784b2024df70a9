"""blendshapes/weights_take: a weight track's controls, mixed from the baked shapes and clipped."""

from types import SimpleNamespace

import numpy as np

from faceforge.blendshapes import weights_take
from faceforge.blendshapes.weights_take import WeightBlocks, mixed_controls


def _baked(k=3, m=2):
    rng = np.random.default_rng(0)
    return {"contractions": rng.uniform(0, 1, (k, m)), "jaw": rng.uniform(-0.2, 0.4, (k, 3)),
            "lids": rng.uniform(-50, 50, (k, 68)), "gaze": np.zeros((k, 4))}


MAPPING = SimpleNamespace(max_contraction=0.8, jaw_limits={"pitch": (0.0, 0.3), "yaw": (-0.1, 0.1),
                                                         "protrusion": (-0.01, 0.02)})


def test_mixed_controls_are_the_weighted_sum_clipped_to_the_ranges():
    baked = _baked()
    w = np.array([[0.5, 0.0], [1.0, 1.0]])
    c, jaw = mixed_controls(w, baked, [2, 0], MAPPING, levers_pitch=10.0)
    raw_c = w @ baked["contractions"][[2, 0]]
    raw_j = w @ baked["jaw"][[2, 0]]
    assert np.allclose(c, np.clip(raw_c, 0.0, 0.8))
    assert np.allclose(jaw[:, 0], np.clip(raw_j[:, 0], 0.0, 0.3))
    assert np.allclose(jaw[:, 2], np.clip(raw_j[:, 2], -0.1, 0.2))    # protrusion limits x the lever
    assert c.max() <= 0.8 and np.any(raw_c > 0.8)                      # the clip did something


def test_weight_blocks_cover_the_take_in_blocks_with_the_lid_faps(monkeypatch):
    monkeypatch.setattr(weights_take, "BLOCK", 4)
    baked = _baked()
    w = np.random.default_rng(1).uniform(0, 1, (10, 2))
    blocks = list(WeightBlocks(w, baked, [1, 2], MAPPING, 1.0, 30.0))
    assert [b.start for b in blocks] == [0, 4, 8] and sum(len(b.c) for b in blocks) == 10
    faps = np.concatenate([b.faps for b in blocks])
    assert np.allclose(faps, w @ baked["lids"][[1, 2]])
    assert all(not np.any(b.angles) for b in blocks)                   # the head does not turn


def _not_additive(drive):
    """A stand-in rig read back: each shape alone reads 0.8 of its drive, and shape 0 pulls shape
    1 back by 0.3 of its own drive (two muscles playing together move less than their sum)."""
    back = 0.8 * drive.copy()
    back[:, 1] -= 0.3 * drive[:, 0]
    return np.clip(back, 0.0, 1.0)


def test_refine_drive_makes_a_non_additive_take_read_back_as_its_weights():
    target = np.array([[0.0, 0.0], [0.5, 0.2], [0.7, 0.4], [0.3, 0.0]])
    drive, errors = weights_take.refine_drive(_not_additive, target, rounds=8, log=lambda *_: None)
    assert len(errors) == 8 and errors[0]["max"] > 0.2                  # played as given, it misses
    assert all(b["rms"] < a["rms"] for a, b in zip(errors, errors[1:]))
    assert np.abs(_not_additive(drive) - target).max() < 0.01            # corrected, it reads back
    assert drive.min() >= 0.0 and drive.max() <= weights_take.DRIVE_MAX
    same, none = weights_take.refine_drive(_not_additive, target, rounds=0)
    assert np.array_equal(same, target) and none == []
