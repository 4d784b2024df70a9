"""The whole bind on a synthetic head with joined lips, simulated in the layered system."""

import numpy as np
import pytest

from faceforge.skin.binding import CRANIUM, MANDIBLE
from faceforge.skin.head import bind_head
from faceforge.skin.layer import SkinSimulation, SkinStiffness
from tests.skin.synthetic import jaw_matrix, lipped_head


@pytest.fixture(scope="module")
def head():
    h = lipped_head()
    v, f = h["skin"]
    bound = bind_head(v, f, h["landmarks"], h["cranium"], h["mandible"], [], max_ray_fraction=0.15)
    return h, bound


def _system(h, bound):
    from faceforge.anatomy.layers import MusculoskeletalSystem

    system = MusculoskeletalSystem.from_parts(h["cranium"], h["mandible"], [])
    sim = SkinSimulation(bound.cut.vertices, bound.cut.faces, bound.binding, SkinStiffness(),
                         weights=bound.weights)
    system.add_layer(sim)
    return system, sim


def test_joined_lips_are_cut_and_bound_to_their_own_bone(head):
    h, bound = head
    cut = bound.cut
    assert cut.case == "shared_ring"
    assert len(cut.source) == len(cut.upper) - 2  # every interior ring vertex duplicated
    status = bound.binding.status
    assert np.all(status[cut.upper[1:-1]] == CRANIUM)
    assert np.all(status[cut.lower[1:-1]] == MANDIBLE)
    assert bound.report["regions"]["face_front"]["fraction"]["bound"] == 1.0


def test_rest_is_a_fixed_point(head):
    h, bound = head
    system, sim = _system(h, bound)
    for _ in range(200):  # the sample heads' tests and the benchmark run 1,000 frames
        system.step()
    diag = np.linalg.norm(np.ptp(sim.rest, axis=0))
    assert np.abs(sim.simulated() - sim.rest).max() < 1e-4 * diag


def test_opening_the_jaw_parts_the_lips_and_keeps_the_skin_outside_the_skull(head):
    import trimesh

    h, bound = head
    system, sim = _system(h, bound)
    cut = bound.cut
    gap0 = np.linalg.norm(sim.rest[cut.upper[1:-1]] - sim.rest[cut.lower[1:-1]], axis=1)
    assert gap0.max() == 0.0
    for _ in range(150):
        system.step(jaw_matrix=jaw_matrix(0.25, h["pivot"]))
    p = sim.positions()
    gap = np.linalg.norm(p[cut.upper[1:-1]] - p[cut.lower[1:-1]], axis=1)
    diag = np.linalg.norm(np.ptp(sim.rest, axis=0))
    assert gap.min() > 0.01 * diag
    # the lower lip went down, the upper lip stayed about where it was
    assert np.all(p[cut.lower[1:-1], 1] < sim.rest[cut.lower[1:-1], 1] - 0.01 * diag)
    for name in ("cranium", "mandible"):
        bone = trimesh.Trimesh(*system.surface(name), process=False)
        closed = trimesh.convex.convex_hull(bone)  # the sphere parts are convex
        assert not closed.contains(p).any()


def test_binding_is_deterministic(head):
    h, bound = head
    v, f = h["skin"]
    again = bind_head(v, f, h["landmarks"], h["cranium"], h["mandible"], [], max_ray_fraction=0.15)
    a, b = bound.as_arrays(), again.as_arrays()
    assert sorted(a) == sorted(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
