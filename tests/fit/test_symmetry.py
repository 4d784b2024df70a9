"""The symmetric rig's plane (faceforge.fit.symmetry, faceforge.fit.files._skin_mirror)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from faceforge.fit.files import _skin_mirror
from faceforge.fit.symmetry import Mirror, exact_plane


def _symmetric_points(seed=3, n=300):
    """``(2n, 3)`` points, the right half the mirror image of the left about x = 0.5."""
    rng = np.random.default_rng(seed)
    left = rng.uniform([0.6, -1, -1], [1.5, 1, 1], (n, 3))
    right = left * [-1, 1, 1] + [1.0, 0, 0]
    return np.vstack([left, right])


def test_exact_plane_recovers_a_symmetric_skin_from_a_slightly_wrong_plane():
    v = _symmetric_points()
    start = Mirror([0.503, 0, 0], [1.0, 0.004, -0.003])     # the landmarks' plane, snapped points a hair off
    assert start.exact_partners(v) is None
    plane = exact_plane(v, start)
    assert plane is not None and plane.exact_partners(v) is not None
    np.testing.assert_allclose(np.abs(plane.normal), [1, 0, 0], atol=1e-12)
    assert abs(plane.side(np.array([0.5, 0, 0]))) < 1e-12


def test_exact_plane_is_none_for_a_skin_that_is_not_symmetric():
    v = _symmetric_points()
    v[5] += [0.0, 0.01, 0.0]                                 # one vertex off its partner's image
    assert exact_plane(v, Mirror([0.5, 0, 0], [1.0, 0, 0])) is None


def test_skin_mirror_is_exact_when_the_landmarks_are_snapped_a_hair_off():
    """A symmetric skin whose quads are split along either diagonal: the detected landmarks snap
    onto that surface a hair off each other's images; the rig's plane must still pair every
    vertex exactly (else the rig was built lopsided and every right entry calibrated alone)."""
    v = _symmetric_points()
    faces = np.arange(len(v)).reshape(-1, 3)
    pairs = {"3.5": 0, "3.6": 300, "3.7": 1, "3.12": 301, "8.3": 2, "8.4": 302, "2.4": 3, "2.5": 303}
    rng = np.random.default_rng(0)
    positions = np.array([v[i] for i in pairs.values()]) + rng.normal(0, 2e-4, (len(pairs), 3))
    lm = SimpleNamespace(ids=list(pairs), positions=positions)
    mirror = _skin_mirror(lm, v, faces, 0.002, log=lambda m: None)
    assert mirror is not None and mirror.exact_partners(v[np.unique(faces)]) is not None
