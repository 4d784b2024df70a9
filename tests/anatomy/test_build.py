"""The real template's muscle map builds and simulates cleanly (templates/skull + templates/muscle_map.yaml).

One layered system (§6) is built once for the module on the template skull with the
paper's stiffness (configs: ``muscle.*.stiffness``) and shared by every test; each
simulation test starts from :meth:`MusculoskeletalSystem.reset`. "Inverted" is
:meth:`Muscle.inverted_faces` (a sheet face turned against the layer below it);
"degenerate" is a face whose area is below 1e-3 of its longest edge squared.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from faceforge.anatomy.muscles.build import build_muscles_on
from faceforge.anatomy.layers import MusculoskeletalSystem, expand_lies_on, underlying_mesh
from faceforge.anatomy.muscles.muscle_map import load_muscle_map, mirrored_name
from faceforge.anatomy.skull import load_skull

ROOT = Path(__file__).resolve().parents[2]
FRAMES = 60
#: projected action line / straight polyline through the map's points (no zigzags)
MAX_LINE_RATIO = 1.3
#: largest distance between a right muscle and its mirrored left twin, fraction of the skull
#: diagonal (the template skull is symmetric to ~1.5 mm at the 99th percentile, 5 mm at worst)
MIRROR_TOL = 0.02
@pytest.fixture(scope="module")
def template():
    skull = load_skull(ROOT / "templates" / "skull")
    specs = load_muscle_map(ROOT / "templates" / "muscle_map.yaml", skull)
    cfg = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())["muscle"]
    stiffness = {kind: cfg[kind]["stiffness"] for kind in ("linear", "sphincter")}
    muscles = build_muscles_on(specs, skull.cranium, skull.mandible, skull.diagonal, stiffness)
    system = MusculoskeletalSystem.from_parts(skull.cranium, skull.mandible, muscles)
    return skull, specs, muscles, system


def inverted_now(system) -> dict[str, int]:
    """Muscle name -> number of sheet faces turned over in the current frame (only > 0)."""
    return system.folded_faces()


def run(system, frames, contractions=None, jaw=None):
    system.reset()
    for _ in range(frames):
        system.step(contractions or {}, jaw)
    v, _ = system.world()
    return v


def test_the_map_keeps_its_muscles_and_layers(template):
    _, specs, muscles, system = template
    kinds = [s.type for s in specs]
    assert kinds.count("linear") == 31 and kinds.count("sphincter") == 1   # Fig. 6 + brow depressors, cheek raisers
    assert tuple(system.layer_indices) == (0, 1, 2, 3, 4)
    assert len(muscles) == 32


def test_rest_meshes_have_no_inverted_or_degenerate_face(template):
    _, _, _, system = template
    inverted, degenerate = system.folded_faces(rest=True), {}
    for name, m in system.muscles.items():
        tri = system.rest_positions(name)[m.faces]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        edge = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2).max(axis=1)
        k = int((area < 1e-3 * edge ** 2).sum())
        if k:
            degenerate[name] = k
    assert inverted == {}
    assert degenerate == {}


def test_no_muscle_at_all_is_folded_at_rest_or_with_the_jaw_open(template):
    skull, _, _, system = template
    system.reset()
    folded = dict(inverted_now(system))
    run(system, FRAMES, None, skull.jaw_transform(skull.jaw.limits["pitch"][1]))
    folded.update(inverted_now(system))
    assert folded == {}


def test_action_lines_follow_their_contour_without_zigzags(template):
    skull, specs, muscles, _ = template
    by_name = {m.name: m for m in muscles}
    too_long = {}
    for spec in specs:
        m = by_name[spec.name]
        deeper = [by_name[n] for n in m.lies_on if n in by_name]
        v, f = underlying_mesh(m.lies_on, skull.cranium, skull.mandible, deeper)
        given = spec.action_lines()
        if spec.type == "sphincter":
            given = {"A1": np.vstack([spec.inner, spec.inner[:1]]), "A3": np.vstack([spec.outer, spec.outer[:1]])}
        for key, line in m.lines.items():
            straight = np.linalg.norm(np.diff(given[key], axis=0), axis=1).sum()
            ratio = line.length(v, f) / straight
            assert ratio > 0.7, f"{spec.name} {key}: projected line shorter than its contour ({ratio:.2f})"
            if ratio > MAX_LINE_RATIO:
                too_long[f"{spec.name}.{key}"] = round(float(ratio), 2)
    assert too_long == {}


def test_left_and_right_muscles_mirror_each_other(template):
    skull, specs, _, system = template
    names = set(system.muscles)
    pairs = [(n, mirrored_name(n)) for n in names if n.endswith("_L")]
    assert len(pairs) == 15 and all(r in names for _, r in pairs)
    flip = np.array([-1.0, 1.0, 1.0])
    for left, right in pairs:
        pl, pr = system.rest_positions(left), system.rest_positions(right)
        assert pl.shape == pr.shape
        gap = np.linalg.norm(pl * flip - pr, axis=1).max() / skull.diagonal
        assert gap < MIRROR_TOL, f"{right} is {gap:.3f} diagonals away from the mirrored {left}"
    for name in names - {n for p in pairs for n in p}:  # midline muscles are their own mirror
        p = system.rest_positions(name)
        centre = p.mean(axis=0)
        assert abs(centre[0]) < MIRROR_TOL * skull.diagonal


def test_rest_is_a_fixed_point_for_200_frames(template):
    skull, _, _, system = template
    system.reset()
    rest, _ = system.world(rest=True)
    v = run(system, 200)
    assert np.abs(v - rest).max() <= 1e-9 * skull.diagonal


def _active(template):
    return [s.name for s in template[1] if s.active]


def test_each_active_muscle_contracted_alone_stays_clean(template):
    _, specs, _, system = template
    bad = {}
    for name in _active(template):
        v = run(system, FRAMES, {name: 1.0})
        assert np.isfinite(v).all(), f"{name} at c = 1 produced NaN"
        inv = inverted_now(system)
        if inv:
            bad[name] = inv
    assert bad == {}


def test_contracting_every_muscle_together_stays_clean(template):
    _, _, _, system = template
    v = run(system, FRAMES, {name: 1.0 for name in _active(template)})
    assert np.isfinite(v).all()
    assert inverted_now(system) == {}


def test_contraction_shortens_the_fibres(template):
    """Named physical check: an active linear muscle at c = 1 is shorter along its fibres."""
    _, specs, _, system = template
    name = "zygomaticus_major_L"
    m = system.muscles[name]
    rest = m.fibre_lengths(system.rest_positions(name)).mean()
    run(system, FRAMES, {name: 1.0})
    assert m.fibre_lengths(system.positions(name)).mean() < 0.8 * rest


@pytest.mark.parametrize("pose", ["open", "open+yaw"])
def test_jaw_opened_to_its_limit_stays_clean(template, pose):
    skull, _, _, system = template
    pitch = skull.jaw.limits["pitch"][1]
    yaw = skull.jaw.limits["yaw"][1] if pose == "open+yaw" else 0.0
    system.reset()
    ramp = FRAMES // 2
    for i in range(FRAMES):
        s = min(1.0, (i + 1) / ramp)
        system.step({}, skull.jaw_transform(s * pitch, s * yaw))
    v, _ = system.world()
    assert np.isfinite(v).all()
    assert inverted_now(system) == {}
    # the mandible really moved: the chin (FDP 2.1) dropped
    chin = skull.landmarks["2.1"]
    T = skull.jaw_transform(pitch, yaw)
    assert (T[:3, :3] @ chin + T[:3, 3])[1] < chin[1] - 0.05 * skull.diagonal


def test_muscles_clear_of_the_mandible_stay_still_when_the_jaw_opens(template):
    """Fig. 7: a layer moves only with what lies below it. Muscles whose layers below reach
    the cranium alone (the levators of the upper lip) do not move (beyond round-off) when the
    jaw opens to its limit; the muscles on the mandible move."""
    skull, specs, _, system = template
    lies = {s.name: set(expand_lies_on(s.lies_on)) for s in specs}

    def reaches_mandible(name, seen=()):
        return any(u == "mandible" or (u in lies and u not in seen and reaches_mandible(u, seen + (name,)))
                   for u in lies[name])

    on_cranium = [n for n in lies if not reaches_mandible(n)]
    assert {"levator_labii_inner_L", "levator_labii_outer_R"} <= set(on_cranium)
    run(system, FRAMES, None, skull.jaw_transform(skull.jaw.limits["pitch"][1]))
    for name in on_cranium:
        d = np.abs(system.positions(name) - system.rest_positions(name)).max()
        assert d < 1e-12 * skull.diagonal, f"{name} moved {d:.3g} with the jaw"
    for name in ("mentalis", "depressor_labii_inferioris_L", "depressor_anguli_R", "platysma_L", "masseter_R"):
        d = np.abs(system.positions(name) - system.rest_positions(name)).max()
        assert d > 0.01 * skull.diagonal, f"{name} lies on the mandible but did not follow it ({d:.3g})"


def test_a_thousand_frames_of_random_contractions_and_jaw_poses_stay_clean(template):
    """Issue 4: random expressions (each active muscle on with probability 0.3, at up to the
    FAP mapping's ``max_contraction``) and jaw poses over the jaw's whole range, a new target
    every second (25 frames) eased toward; no NaN, no muscle face turned over once the last
    pose is held, and none in any frame."""
    skull, specs, _, system = template
    cap = yaml.safe_load((ROOT / "templates" / "fap_mapping.yaml").read_text())["max_contraction"]
    active = _active(template)
    rng = np.random.default_rng(7)
    lo, hi = np.array([skull.jaw.limits["pitch"], skull.jaw.limits["yaw"]]).T
    c, jaw = np.zeros(len(active)), np.zeros(2)
    folded = {}
    system.reset()
    for frame in range(1000):
        if frame % 25 == 0:
            target_c = rng.uniform(0.0, cap, len(active)) * (rng.uniform(size=len(active)) < 0.3)
            target_jaw = rng.uniform(lo, hi)
        c += 0.2 * (target_c - c)
        jaw += 0.2 * (target_jaw - jaw)
        system.step(dict(zip(active, c)), skull.jaw_transform(*jaw))
        for name, k in inverted_now(system).items():
            folded[name] = max(folded.get(name, 0), k)
    assert np.isfinite(system.world()[0]).all()
    for _ in range(FRAMES):
        system.step(dict(zip(active, c)), skull.jaw_transform(*jaw))
    assert inverted_now(system) == {}, "folded after holding the last pose"
    assert folded == {}


def test_compiled_layer_targets_equal_the_per_muscle_twin(template):
    """LinearTargets (one numba call per layer) against Muscle.targets_from_line_points, to the
    bit, on the real map with random contractions (out of range ones clipped) and jaw poses."""
    skull, _, _, system = template
    rng = np.random.default_rng(1)
    names = list(system.muscles)
    system.reset()
    checked = 0
    for _ in range(12):
        c = dict(zip(names, rng.uniform(-0.2, 1.2, len(names)) * (rng.uniform(size=len(names)) < 0.6)))
        system.step(c, skull.jaw_transform(rng.uniform(0.0, 0.3), rng.uniform(-0.05, 0.05)))
        for layer in system._layers:
            if layer.linear is None:
                continue
            pts = np.einsum("ij,ijk->ik", layer.bary, system.world()[0][layer.vids])
            twin = [m.targets_from_line_points(c.get(m.name, 0.0), {k: pts[sl] for k, sl in own.items()})
                    for m, s, own in zip(layer.muscles, layer.slots, layer.pieces) if m.kind == "linear" and len(s)]
            assert np.array_equal(layer.linear(pts, c), np.concatenate(twin)), layer.index
            checked += 1
    assert checked >= 12 * 4
    system.reset()


def test_a_layer_built_kind_by_kind_steps_like_its_muscles_one_by_one(template):
    """add_muscles_to_builder (four blocks per layer) against Muscle.add_to_builder per muscle
    (four blocks per muscle): in builder order each muscle's projections are the same sequence
    and no constraint crosses muscles, so a step from a perturbed state gives the same bits."""
    from faceforge.anatomy.muscles.muscle import add_muscles_to_builder
    from faceforge.pbd import ModelBuilder, Solver, SolverSettings

    _, specs, muscles, _ = template
    group = [m for m in muscles if m.layer == 2]
    assert len(group) >= 4
    states = []
    for kind_by_kind in (False, True):
        b = ModelBuilder()
        if kind_by_kind:
            _, slots = add_muscles_to_builder(b, group)
        else:
            slots = [m.add_to_builder(b)[1] for m in group]
        model = b.finalize()
        solver = Solver(model, SolverSettings(iterations=10, colouring=False))
        state, control = model.state(), model.control()
        rng = np.random.default_rng(3)
        state.positions[:] += rng.normal(scale=0.05, size=state.positions.shape)
        for m, s in zip(group, slots):          # targets: each muscle's rest samples, shifted
            control.position_targets[s] = m.rest_positions[m.bound] + 0.1
        for _ in range(5):
            solver.step(state, state, control, 1.0 / 25.0)
        states.append(state.positions.copy())
    assert np.array_equal(states[0], states[1])


def test_a_muscle_that_cannot_be_built_is_a_one_line_error_naming_it(template):
    """A fit whose muscle collapsed (every point of the mentalis on one spot): the build names
    the muscle (TemplateError), and the animate stage turns that into a StageError on fit.npz."""
    from faceforge.exceptions import StageError, TemplateError
    from faceforge.io.config import load_config
    from faceforge.animation.rig import muscle_system

    skull, specs, _, system = template
    points = [s.points() for s in specs]
    k = [s.name for s in specs].index("mentalis")
    points[k] = np.repeat(points[k][:1], len(points[k]), axis=0)
    with pytest.raises(TemplateError, match="muscle 'mentalis' cannot be built"):
        build_muscles_on([specs[k].with_points(points[k])], skull.cranium, skull.mandible, skull.diagonal)
    fit = {"muscle_map_names": np.array([s.name for s in specs]),
           "muscle_map_start": np.cumsum([0] + [len(p) for p in points]),
           "muscle_map_points": np.vstack(points)}
    with pytest.raises(StageError, match=r"^fit\.npz: muscle 'mentalis' cannot be built .*rerun `faceforge fit`"):
        muscle_system(fit, skull.cranium, skull.mandible, system.settings, load_config(), lambda m: None)


def test_the_lips_contact_line_lies_on_the_teeth_only_with_inner_on_bone(template):
    """``inner_on_bone`` (muscle.sphincter.inner_on_bone): the orbicularis oris' inner loop
    (A1) is projected onto the skull's faces only, its outer loop (A3) onto every body it lies
    on (the lip muscles' insertions among them). (The module's other tests build the template
    without it: on the unfitted template skull it turns one ring face over at rest; the fitted
    samples' rigs have the same folded faces with and without it.)"""
    skull, specs, _, _ = template
    ring = [s for s in specs if s.type == "sphincter"]
    built = next(m for m in build_muscles_on(specs, skull.cranium, skull.mandible, skull.diagonal, inner_on_bone=True)
                 if m.name == ring[0].name)
    lies = expand_lies_on(ring[0].lies_on)
    assert lies[:2] == ("cranium", "mandible")
    n_bone = len(skull.cranium[1]) + len(skull.mandible[1])
    assert np.all(built.lines["A1"].points.face_ids < n_bone)
    assert np.all(built.lines["A1"].points.bary.sum(axis=1) > 0.999)


def test_the_cheek_raiser_follows_the_orbits_rim_and_lifts_the_cheek(template):
    """The cheek raiser's origin (A3, fitted to the rim by tools/cheek_rim.py) lies on the bone
    as smoothly as its polyline (a straight origin across the rim zigzagged to 1.74 times its
    length); contracted, its insertion moves up toward the eye."""
    skull, specs, muscles, system = template
    spec = next(s for s in specs if s.name == "orbicularis_oculi_lower_L")
    m = next(x for x in muscles if x.name == spec.name)
    v, f = underlying_mesh(m.lies_on, skull.cranium, skull.mandible, [x for x in muscles if x.name in m.lies_on])
    given = np.linalg.norm(np.diff(spec.origin, axis=0), axis=1).sum()
    assert m.lines["A3"].length(v, f) / given < 1.05
    top = system.rest_positions(m.name)
    run(system, FRAMES, {m.name: 1.0})
    lift = (system.positions(m.name) - top)[:, 1]
    assert lift.max() > 0.02 * skull.diagonal and lift.min() > -0.002 * skull.diagonal
