"""skin.joined: a vertex carried by several muscles follows the one moving most."""

import numpy as np

from faceforge.skin.joined import join, join_args, join_plain, joined_groups


def test_groups_only_vertices_with_two_carried_anchors():
    ids = np.array([0, 1, 1, 2, 2, 2, 3, 3])
    carried = np.array([True, True, True, True, False, True, True, False])
    rows, starts = joined_groups(ids, carried)
    groups = [sorted(rows[a:b]) for a, b in zip(starts[:-1], starts[1:])]
    assert groups == [[1, 2], [3, 5]]        # vertex 3 has one carried anchor only


def test_join_follows_the_muscle_that_moves_and_keeps_common_motion():
    rest = np.zeros((2, 3))
    ids = np.array([0, 0, 1, 1])
    rows, starts, p0 = join_args(rest, ids, np.ones(4, bool))
    t = np.array([[-3.0, -1.0, 0.0], [0.0, 0.0, 0.0],       # one pulls, the other is still
                  [0.0, 2.0, 0.0], [0.0, 2.0, 0.0]])        # both carried alike
    out = join_plain(t.copy(), rows, starts, p0)
    np.testing.assert_allclose(out[0], [-3.0, -1.0, 0.0])
    np.testing.assert_allclose(out[1], [-3.0, -1.0, 0.0])
    np.testing.assert_allclose(out[2:], [[0.0, 2.0, 0.0]] * 2)
    # the mean of before would have stopped the first vertex half way
    assert np.linalg.norm(out[1]) > 1.9 * np.linalg.norm(t[:2].mean(axis=0))


def test_compiled_twin_and_rest_is_a_fixed_point():
    rng = np.random.default_rng(3)
    rest = rng.normal(size=(5, 3))
    ids = np.array([0, 0, 1, 2, 2, 2, 4])
    rows, starts, p0 = join_args(rest, ids, np.ones(len(ids), bool))
    t = rest[ids] + rng.normal(size=(len(ids), 3))
    a = join_plain(t.copy(), rows, starts, p0)
    b = t.copy()
    join(b, rows, starts, p0)
    np.testing.assert_allclose(a, b, atol=1e-12)
    still = rest[ids].copy()
    join(still, rows, starts, p0)
    np.testing.assert_array_equal(still, rest[ids])
    np.testing.assert_array_equal(a[2], t[2])
