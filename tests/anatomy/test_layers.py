"""The layered musculoskeletal system (§6) on the synthetic head of conftest.py."""

import numpy as np
import pytest

from faceforge.anatomy.layers import MusculoskeletalSystem, expand_lies_on
from faceforge.exceptions import TemplateError

from tests.anatomy.conftest import jaw_matrix, linear_on, split_skull


@pytest.fixture
def system(head):
    cranium, mandible, muscles = head
    return MusculoskeletalSystem.from_parts(cranium, mandible, muscles)


def snapshot(system):
    return {n: system.positions(n) for n in system.names}


def test_layers_and_world(system, head):
    assert system.layer_indices == (0, 1)
    assert system.names[:2] == ("cranium", "mandible")
    v, f = system.world()
    for name in system.names:
        sl = system.vertex_range(name)
        np.testing.assert_array_equal(v[sl], system.positions(name))
        np.testing.assert_array_equal(f[system.face_range(name)] - sl.start, system.faces(name))
    assert set(system.body_of_faces([0, len(f) - 1])) == {"cranium", "oris"}
    assert expand_lies_on(["skull", "frontalis", "cranium"]) == ("cranium", "mandible", "frontalis")


def test_compiled_surface_gather_matches_its_einsum_twin():
    """``bary_points`` (the per-frame gather of action lines and skin anchors) gives the bits
    of ``np.einsum("ij,ijk->ik", bary, v[ids])``, which the rest targets were computed with."""
    from faceforge.anatomy.muscles.targets import bary_points

    rng = np.random.default_rng(7)
    v = rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-3, 3, size=(500, 1))
    for k in (0, 1, 5, 300):
        ids = rng.integers(0, len(v), size=(k, 3))
        bary = rng.dirichlet([1.0, 1.0, 1.0], size=k)
        bary[::2] = rng.normal(size=bary[::2].shape)       # outside the triangle too
        twin = np.einsum("ij,ijk->ik", bary, v[ids])
        assert np.array_equal(bary_points(bary, ids, v), twin)
        out = np.full((k, 3), np.nan)
        assert bary_points(bary, ids, v, out) is out and np.array_equal(out, twin)
    view = v.view()
    view.flags.writeable = False                           # the system's world_view()
    assert np.array_equal(bary_points(bary, ids, view), twin)


def test_world_view_is_the_current_world_read_only(system):
    system.step({"oris": 1.0})
    view = system.world_view()
    assert np.array_equal(view, system.world()[0]) and not view.flags.writeable


def test_rest_is_a_fixed_point(system):
    rest = snapshot(system)
    for _ in range(100):
        system.step({}, np.eye(4))
    for name, p in snapshot(system).items():
        np.testing.assert_allclose(p, rest[name], atol=1e-12, err_msg=name)


def test_jaw_opening_moves_mandible_muscles_only(system):
    """A 15 degree jaw opening: muscles on the mandible follow it, those on the cranium
    (and those lying on cranium-only muscles) do not move at all."""
    rest = snapshot(system)
    T = jaw_matrix(np.radians(15))
    for k in range(100):
        system.step({}, jaw_matrix(np.radians(15) * min(1.0, (k + 1) / 25)))
    now = snapshot(system)
    rigid = lambda p: p @ T[:3, :3].T + T[:3, 3]  # noqa: E731
    np.testing.assert_allclose(now["mandible"], rigid(rest["mandible"]), atol=1e-12)
    np.testing.assert_array_equal(now["cranium"], rest["cranium"])
    # lying only on the mandible: the muscle is carried rigidly (its targets are)
    moved = np.linalg.norm(rigid(rest["mentalis"]) - rest["mentalis"], axis=1).min()
    assert moved > 0.1
    assert np.abs(now["mentalis"] - rigid(rest["mentalis"])).max() < 0.02 * moved
    # lying on both: moves, but less than the mandible does
    d_mass = np.linalg.norm(now["masseter"] - rest["masseter"], axis=1)
    assert d_mass.max() > 0.5 * moved
    # the sphincter around the cut: its lower half follows the jaw
    assert np.linalg.norm(now["oris"] - rest["oris"], axis=1).max() > 0.5 * moved
    # cranium-only, and on cranium-only muscles: still
    for name in ("frontalis", "zygomaticus"):
        np.testing.assert_allclose(now[name], rest[name], atol=1e-12, err_msg=name)


def test_deeper_layers_ignore_shallower_ones(head):
    """Fig. 7: the same inputs give the same deep layer, whatever lies on top of it."""
    cranium, mandible, muscles = head
    deep = [m for m in muscles if m.layer == 0]
    full = MusculoskeletalSystem.from_parts(cranium, mandible, muscles)
    alone = MusculoskeletalSystem.from_parts(cranium, mandible, deep)
    rng = np.random.default_rng(4)
    for k in range(60):
        c = {m.name: float(rng.random()) for m in muscles}
        jaw = jaw_matrix(np.radians(10) * rng.random())
        full.step(c, jaw)
        alone.step({n: v for n, v in c.items() if n in alone.muscles}, jaw)
    for m in deep:
        np.testing.assert_array_equal(full.positions(m.name), alone.positions(m.name))
    # contracting only the shallow layer leaves every deeper body exactly at rest
    full.reset()
    rest = snapshot(full)
    for _ in range(50):
        full.step({"zygomaticus": 1.0, "oris": 1.0})
    for m in deep:
        np.testing.assert_allclose(full.positions(m.name), rest[m.name], atol=1e-12)
    assert np.abs(full.positions("zygomaticus") - rest["zygomaticus"]).max() > 0.05


def test_a_deeper_contraction_drives_the_muscle_on_top(system):
    rest = snapshot(system)
    for _ in range(60):
        system.step({"frontalis": 1.0})
    assert np.abs(system.positions("zygomaticus") - rest["zygomaticus"]).max() > 0.02
    np.testing.assert_allclose(system.positions("mentalis"), rest["mentalis"], atol=1e-12)


def test_thousand_random_frames_stay_finite_and_uninverted(system):
    """Smooth random contractions (a new random key every second, linear in between, from
    rest) and jaw pitch in [0, 15] degrees: no NaN, no inverted muscle triangle."""
    rng = np.random.default_rng(7)
    names = list(system.muscles)
    keys = rng.random((42, len(names)))
    jaw_keys = rng.random(42)
    keys[0], jaw_keys[0] = 0.0, 0.0
    x = np.arange(42)
    inverted = {}
    for k in range(1000):
        t = k / 25
        c = {n: float(np.interp(t, x, keys[:, j])) for j, n in enumerate(names)}
        system.step(c, jaw_matrix(np.radians(15) * np.interp(t, x, jaw_keys)))
        v, f = system.world()
        assert np.all(np.isfinite(v)), f"NaN at frame {k}"
        for n in system.folded_faces():
            inverted.setdefault(n, k)
    assert not inverted, f"first inverted frame per muscle: {inverted}"


def test_extra_layer_reads_solved_positions_of_the_same_frame(system):
    seen = []

    class Probe:
        def step(self, sys_, dt):
            seen.append((sys_.positions("mandible")[0].copy(), dt))

    system.add_layer(Probe())
    T = jaw_matrix(np.radians(5))
    system.step({}, T, dt=0.02)
    assert seen[0][1] == 0.02
    np.testing.assert_allclose(seen[0][0], system.positions("mandible")[0])
    np.testing.assert_allclose(seen[0][0], system.rest_positions("mandible")[0] @ T[:3, :3].T + T[:3, 3])
    with pytest.raises(TypeError):
        system.add_layer(object())


def test_reset_restores_rest(system):
    rest = snapshot(system)
    for _ in range(20):
        system.step({"frontalis": 0.8, "oris": 0.5}, jaw_matrix(0.2))
    system.reset()
    for name, p in snapshot(system).items():
        np.testing.assert_array_equal(p, rest[name])


def test_invalid_assemblies_are_template_errors(head):
    cranium, mandible, muscles = head
    with pytest.raises(TemplateError, match="zygomaticus"):  # lies on a muscle not given
        MusculoskeletalSystem.from_parts(cranium, mandible, [m for m in muscles if m.name != "frontalis"])
    v, f = cranium
    same_layer = linear_on("up", v, f, [(-0.1, 0.5), (0.1, 0.5)], [(-0.1, 0.3), (0.1, 0.3)],
                           lies_on=("frontalis",), layer=0)
    with pytest.raises(TemplateError, match="must be deeper"):
        MusculoskeletalSystem.from_parts(cranium, mandible, muscles + [same_layer])
    with pytest.raises(TemplateError, match="duplicate"):
        MusculoskeletalSystem.from_parts(cranium, mandible, muscles + [muscles[0]])
    system = MusculoskeletalSystem.from_parts(cranium, mandible, muscles)
    with pytest.raises(KeyError, match="frontalis"):
        system.step({"frontalus": 0.5})
    with pytest.raises(KeyError, match="oris.protrude"):
        system.step({"oris.protrude": 0.5, "frontalis.protrude": 0.5})
    with pytest.raises(ValueError, match="rigid"):
        system.step({}, np.diag([1.0, 2.0, 1.0, 1.0]))


def test_the_protrusion_control_moves_the_sphincter_forward(head):
    """``controls`` lists the muscles, then the sphincter's protrusion drive; with a
    protrusion the drive moves the sphincter along its forward direction and leaves the
    bones in place; a zero drive steps as no drive, to the bit."""
    from dataclasses import replace

    cranium, mandible, muscles = head
    muscles = [replace(m, protrusion=0.5) if m.kind == "sphincter" else m for m in muscles]
    system = MusculoskeletalSystem.from_parts(cranium, mandible, muscles)
    assert system.controls == tuple(system.muscles) + ("oris.protrude", "oris.lower")
    rest = snapshot(system)
    twin = MusculoskeletalSystem.from_parts(cranium, mandible, muscles)
    system.step({"oris.protrude": 0.0})
    twin.step({})
    assert all(np.array_equal(system.positions(n), twin.positions(n)) for n in system.names)
    for _ in range(20):
        system.step({"oris.protrude": 1.0})
    fw = system.muscles["oris"].forward
    d = (system.positions("oris") - rest["oris"]) @ fw
    assert d.mean() > 0.01 * np.ptp(rest["oris"], axis=0).max()
    for bone in ("cranium", "mandible"):
        assert np.array_equal(system.positions(bone), rest[bone])


def test_split_skull_parts_are_disjoint():
    (cv, cf), (mv, mf) = split_skull(2)
    assert len(cf) and len(mf) and cf.max() < len(cv) and mf.max() < len(mv)
