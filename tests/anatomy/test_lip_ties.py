"""The lips' ties (anatomy.muscles.modiolus.LipTie): a lip of the sphincter rides on the muscle
pair inserting into it, on the synthetic head of conftest.py with a depressor of the lower lip
on each side (issue 25: the depressor labii inferioris moved the lower lip 1.9 mm at most)."""

import numpy as np
import pytest

from faceforge.anatomy.layers import MusculoskeletalSystem
from faceforge.anatomy.muscles.modiolus import LipTie, attach_lip_ties, attach_modiolus, lip_arc

from tests.anatomy.conftest import ring_with_pair

CENTRE, INNER, OUTER = (0.0, -0.3), (0.15, 0.07), (0.32, 0.17)


@pytest.fixture(scope="module")
def parts():
    """Skull, a depressor of the lower lip per side (layer 0, on the bone, from below the chin to
    the lower lip beside the midline) and the ring (layer 1, on the bone only: untied, the
    depressors cannot move it)."""
    return ring_with_pair("depressor_labii_inferioris", [(0.06, -0.78), (0.16, -0.76)],
                          [(0.03, -0.41), (0.12, -0.40)], INNER, CENTRE, OUTER)


def lip_motion(parts, tie: bool, controls: dict, frames: int = 60):
    """Mean displacement of the ring's bottom particles on the lower lip's middle (|x| < 0.08,
    below the centre) and on the upper lip (above it), after ``frames`` steps."""
    system = MusculoskeletalSystem.from_parts(*parts)
    if tie:
        assert len(attach_lip_ties(system, lower=("depressor_labii_inferioris",), radius=0.25)) == 1
    rest = system.rest_positions("orbicularis_oris")
    for _ in range(frames):
        system.step(controls)
    d = system.positions("orbicularis_oris") - rest
    mid = np.abs(rest[:, 0]) < 0.08
    lower = d[mid & (rest[:, 1] < CENTRE[1] - 0.05)].mean(axis=0)
    upper = d[rest[:, 1] > CENTRE[1] + 0.05].mean(axis=0)
    return lower, upper, system


def test_the_lower_lip_follows_its_depressors_only_with_the_tie(parts):
    both = {"depressor_labii_inferioris_L": 1.0, "depressor_labii_inferioris_R": 1.0}
    lower, upper, system = lip_motion(parts, True, both)
    ins = system.positions("depressor_labii_inferioris_L") - system.rest_positions("depressor_labii_inferioris_L")
    t = system.muscles["depressor_labii_inferioris_L"].topology
    pull = ins[t.bottom(t.h - 1, np.arange(t.w))].mean(axis=0)
    assert pull[1] < -0.05                         # the insertion moves down
    assert lower[1] < 0.5 * pull[1]                # the lower lip goes with it
    assert np.abs(upper).max() < 0.25 * abs(lower[1])  # the upper lip stays (the ring drags it a little)
    free, _, _ = lip_motion(parts, False, both)
    assert abs(free[1]) < 0.1 * abs(lower[1])      # untied, the ring lies on the bone alone


def test_rest_is_a_fixed_point_and_the_ring_alone_is_untouched(parts):
    lower, upper, _ = lip_motion(parts, True, {}, frames=5)
    assert np.abs(lower).max() < 1e-12 and np.abs(upper).max() < 1e-12
    a = lip_motion(parts, True, {"orbicularis_oris": 0.5}, frames=20)
    b = lip_motion(parts, False, {"orbicularis_oris": 0.5}, frames=20)
    np.testing.assert_allclose(np.r_[a[0], a[1]], np.r_[b[0], b[1]], atol=1e-12)   # no depressor active


def test_one_side_pulls_its_own_side_more(parts):
    system = MusculoskeletalSystem.from_parts(*parts)
    attach_lip_ties(system, lower=("depressor_labii_inferioris",), radius=0.25)
    rest = system.rest_positions("orbicularis_oris")
    for _ in range(60):
        system.step({"depressor_labii_inferioris_L": 1.0})
    d = system.positions("orbicularis_oris") - rest
    low = rest[:, 1] < CENTRE[1] - 0.05
    left = d[low & (rest[:, 0] > 0.05) & (rest[:, 0] < 0.2)][:, 1].mean()
    right = d[low & (rest[:, 0] < -0.05) & (rest[:, 0] > -0.2)][:, 1].mean()
    assert left < 2.0 * right < 0.0 or (left < 0.0 and abs(right) < 0.5 * abs(left))


def test_the_ties_chain_after_the_modiolus(parts):
    """A lip tie and the modiolus on one ring: both kept, applied in order."""
    system = MusculoskeletalSystem.from_parts(*parts)
    assert attach_modiolus(system, muscles=("depressor_labii_inferioris",), radius=0.3) is not None
    assert len(attach_lip_ties(system, lower=("depressor_labii_inferioris",))) == 1
    assert len(system._ties["orbicularis_oris"]) == 2
    system.clear_loop_ties("orbicularis_oris")
    assert "orbicularis_oris" not in system._ties


def test_lip_arc_splits_a_loop_at_its_corners_by_order_not_height():
    # a closed inner loop whose two lips touch (the same heights): the order tells them apart
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    pts = np.stack([np.cos(ang), 1e-3 * np.sign(np.sin(ang)), np.zeros(12)], 1)
    lower = lip_arc(pts, [1.0, 0.0, 0.0], True)
    upper = lip_arc(pts, [1.0, 0.0, 0.0], False)
    np.testing.assert_array_equal(lower, (np.sin(ang) < -1e-9).astype(float))
    np.testing.assert_array_equal(upper, (np.sin(ang) > 1e-9).astype(float))
    assert lower[0] == upper[0] == lower[6] == upper[6] == 0.0      # the corners: neither lip's
    rolled = lip_arc(np.roll(pts, 5, axis=0), [1.0, 0.0, 0.0], True)
    np.testing.assert_array_equal(rolled, np.roll(lower, 5))        # wherever the loop starts


def test_the_tie_ramps_in_and_weighs_by_distance_on_its_lip():
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    rest = {"A3": np.stack([np.cos(ang), 0.5 * np.sin(ang), np.zeros(16)], 1)}
    world = np.zeros((4, 3))
    world[0] = [0.3, -0.5, 0.0]     # side 0's insertion end on the lower lip
    world[1] = [-0.3, -0.5, 0.0]
    tie = LipTie(rest, [([0], [[0]]), ([1], [[1]])], world, radius=0.25, ramp=0.1)
    w = tie.weights["A3"]
    assert np.all(w[:, np.sin(ang) >= -1e-9] == 0.0)              # nothing on the upper lip or corners
    near = int(np.argmin(np.linalg.norm(rest["A3"] - world[0], axis=1)))
    assert w[0, near] == w[0].max() > 0.9
    moved = world.copy()
    moved[0] += [0.0, -0.2, 0.0]
    for c, g in ((0.0, 0.0), (0.05, 0.5), (0.3, 1.0)):
        out = tie.apply(rest, moved, np.array([c, 0.0]))
        np.testing.assert_allclose(out["A3"] - rest["A3"], (g * w[0])[:, None] * [0.0, -0.2, 0.0], atol=1e-15)


def test_both_sides_share_the_middle_whatever_their_order():
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    rest = {"A3": np.stack([np.cos(ang), 0.5 * np.sin(ang), np.zeros(16)], 1)}
    world = np.array([[0.2, -0.5, 0.0], [-0.2, -0.5, 0.0]])
    moved = world + [[0.1, -0.2, 0.0], [-0.1, -0.2, 0.0]]     # mirror-image pulls
    tie = LipTie(rest, [([0], [[0]]), ([1], [[1]])], world, radius=0.4, ramp=0.1)
    swapped = LipTie(rest, [([1], [[1]]), ([0], [[0]])], world, radius=0.4, ramp=0.1)
    c = np.array([1.0, 1.0])
    a = tie.apply(rest, moved, c)["A3"] - rest["A3"]
    np.testing.assert_allclose(a, swapped.apply(rest, moved, c)["A3"] - rest["A3"], atol=1e-15)
    mid = int(np.argmin(np.linalg.norm(rest["A3"] - [0.0, -0.5, 0.0], axis=1)))
    np.testing.assert_allclose(a[mid], [0.0, -0.2, 0.0], atol=1e-12)   # both pulls, mirrored: straight down
    mirror = np.array([int(np.argmin(np.linalg.norm(rest["A3"] - p * [-1, 1, 1], axis=1))) for p in rest["A3"]])
    np.testing.assert_allclose(a[mirror] * [-1, 1, 1], a, atol=1e-12)


def test_a_pair_the_map_lacks_is_a_config_error(parts):
    """A user's typo in ``muscle.sphincter.lip_ties.lower`` is named, not skipped."""
    from faceforge.exceptions import ConfigError

    system = MusculoskeletalSystem.from_parts(*parts)
    with pytest.raises(ConfigError, match=r"lip_ties\.lower: .*depresor_labii_L"):
        attach_lip_ties(system, lower=("depresor_labii",))
