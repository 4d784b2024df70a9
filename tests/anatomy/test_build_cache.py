"""The built muscles kept on disk (faceforge.anatomy.muscles.build_cache, rig.built_muscles).

A stored build must come back bit for bit (every field, dtype, memory order, arrays shared
between fields still shared, no ``__init__`` rerun) and a simulation of it must step to the same
bits; anything the key does not cover must not be read back.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from faceforge.anatomy.layers import MusculoskeletalSystem
from faceforge.anatomy.muscles import build_cache
from faceforge.anatomy.muscles.build_cache import cache_key, decode, encode, load_muscles, save_muscles


def assert_same(a, b, path="muscles"):
    """``a`` and ``b`` equal to the bit, type for type."""
    assert type(a) is type(b), path
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert a.flags.c_contiguous == b.flags.c_contiguous and a.flags.f_contiguous == b.flags.f_contiguous, path
        assert a.tobytes() == b.tobytes(), path
    elif dataclasses.is_dataclass(a) or type(a).__module__.startswith("faceforge."):
        assert set(vars(a)) == set(vars(b)), path
        for name in vars(a):
            assert_same(getattr(a, name), getattr(b, name), f"{path}.{name}")
    elif isinstance(a, dict):
        assert list(a) == list(b), path
        for k in a:
            assert_same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), path
    else:
        assert a == b, path


def test_stored_muscles_come_back_bit_for_bit(head, tmp_path):
    cranium, mandible, muscles = head
    assert save_muscles(tmp_path, "k1", muscles) is not None
    back = load_muscles(tmp_path, "k1")
    assert back is not None and back is not muscles
    assert_same(muscles, back)


def test_a_stored_system_steps_to_the_same_bits(head, tmp_path):
    cranium, mandible, muscles = head
    save_muscles(tmp_path, "k1", muscles)
    systems = [MusculoskeletalSystem.from_parts(cranium, mandible, m) for m in (muscles, load_muscles(tmp_path, "k1"))]
    c = np.zeros(len(systems[0].controls))
    c[: len(c) // 2] = 0.6
    for _ in range(5):
        for s in systems:
            s.step(c, None, 1.0 / 25.0)
    for name in systems[0].names:
        assert systems[0].surface(name)[0].tobytes() == systems[1].surface(name)[0].tobytes(), name


def test_decode_does_not_rerun_init(head, tmp_path, monkeypatch):
    """A muscle's ``__post_init__`` rebuilds its constraints: the stored ones come back instead."""
    from faceforge.anatomy.muscles.muscle import Muscle

    muscles = head[2]
    save_muscles(tmp_path, "k1", muscles)

    def boom(self):
        raise AssertionError("__post_init__ ran")

    monkeypatch.setattr(Muscle, "__post_init__", boom)
    assert len(load_muscles(tmp_path, "k1")) == len(muscles)


def test_shared_arrays_stay_shared_and_memory_order_is_kept():
    a = np.asfortranarray(np.arange(12.0).reshape(3, 4))
    arrays: list = []
    back = decode(encode({"x": a, "y": (a, [1, 2.5, True, None, "s"])}, arrays), arrays)
    assert len(arrays) == 1 and back["x"] is back["y"][0] and back["x"].flags.f_contiguous
    assert back["y"][1] == [1, 2.5, True, None, "s"] and type(back["y"][1][2]) is bool


def test_misses(head, tmp_path):
    muscles = head[2]
    assert load_muscles(tmp_path, "none") is None                       # no file
    path = save_muscles(tmp_path, "k1", muscles)
    path.rename(build_cache.cache_path(tmp_path, "k2"))               # a file under another key
    assert load_muscles(tmp_path, "k2") is None
    build_cache.cache_path(tmp_path, "k3").write_bytes(b"not an npz")  # unreadable
    assert load_muscles(tmp_path, "k3") is None
    assert save_muscles(tmp_path, "k4", [np.float32(1.0)]) is None     # a numpy scalar: not stored
    assert save_muscles(tmp_path, "k4", [object()]) is None
    assert not build_cache.cache_path(tmp_path, "k4").exists()


def test_keeps_the_newest_files(tmp_path, monkeypatch):
    monkeypatch.setattr(build_cache, "KEEP", 2)
    import os

    for i in range(4):
        save_muscles(tmp_path, f"k{i}", [np.zeros(2)])
        os.utime(build_cache.cache_path(tmp_path, f"k{i}"), (1000 + i, 1000 + i))
    save_muscles(tmp_path, "k9", [np.zeros(2)])
    assert sorted(p.name for p in tmp_path.glob("muscles-*.npz")) == ["muscles-k3.npz", "muscles-k9.npz"]


def test_the_key_covers_values_files_and_code(tmp_path, monkeypatch):
    f = tmp_path / "map.yaml"
    f.write_text("a: 1\n")
    base = [("points", np.zeros((2, 3))), ("file", f), ("stiffness", {"bend": 0.4})]
    k = cache_key(base)
    assert cache_key(base) == k
    assert cache_key([("points", np.ones((2, 3))), *base[1:]]) != k
    assert cache_key([("points", np.zeros((3, 2))), *base[1:]]) != k          # shape
    assert cache_key([("points", np.zeros((2, 3), np.float32)), *base[1:]]) != k   # dtype
    assert cache_key([*base[:2], ("stiffness", {"bend": 0.5})]) != k
    f.write_text("a: 2\n")
    assert cache_key(base) != k
    f.write_text("a: 1\n")
    monkeypatch.setattr(build_cache, "_code_digest", "edited")
    assert cache_key(base) != k


def test_built_muscles_reads_back_what_the_build_kept(head, tmp_path, monkeypatch):
    """rig.built_muscles: one build per key; a config key of the build misses."""
    from faceforge.animation import rig
    from faceforge.io.config import load_config

    cranium, mandible, muscles = head
    fit = {"muscle_map_names": np.array(["frontalis"]), "muscle_map_start": np.array([0, 2]),
           "muscle_map_points": np.zeros((2, 3))}
    builds = []

    def build(*args):
        builds.append(1)
        return muscles

    monkeypatch.setattr(rig, "_build_muscles", build)
    config = load_config()
    first = rig.built_muscles(fit, cranium, mandible, config, tmp_path)
    second = rig.built_muscles(fit, cranium, mandible, config, tmp_path)
    assert len(builds) == 1 and first is muscles
    assert_same(muscles, second)
    rig.built_muscles(fit, cranium, mandible, load_config(sets=["muscle.sphincter.protrusion=0.123"]), tmp_path)
    assert len(builds) == 2
    rig.built_muscles({**fit, "muscle_map_points": np.ones((2, 3))}, cranium, mandible, config, tmp_path)
    assert len(builds) == 3
    rig.built_muscles(fit, cranium, mandible, config, None)                  # no cache: builds
    assert len(builds) == 4


def test_the_build_reads_only_the_keys_its_cache_key_holds():
    """Every config key ``rig._build_muscles`` reads is in ``rig.BUILD_KEYS`` (else a change of it
    would read a stale build back)."""
    import inspect
    import re

    from faceforge.animation import rig

    read = set(re.findall(r'config\.get\("([^"]+)"\)', inspect.getsource(rig._build_muscles)))
    assert read and read <= set(rig.BUILD_KEYS), read - set(rig.BUILD_KEYS)


def _skin_around(cranium, mandible, radius=1.04):
    """A skin a little outside the synthetic skull (its vertices scaled out from the centre)."""
    v = np.vstack([cranium[0], mandible[0]])
    return v * radius


def test_stored_guards_push_the_skin_out_the_same(head, tmp_path):
    """The skull guard and the bone collision (plain objects of faceforge.animation.guards, their
    grids plain objects of faceforge.geometry) come back as they were built: the same pushes."""
    from faceforge.anatomy.muscles.build_cache import cached
    from faceforge.animation.guards.bone_collision import BoneCollision
    from faceforge.animation.guards.skull import SkullGuard

    cranium, mandible, _ = head
    rest = _skin_around(cranium, mandible)
    bones = {"cranium": cranium, "mandible": mandible}
    builds = []

    def build_guard():
        builds.append("guard")
        return SkullGuard(rest, bones, reach=0.2, keep=0.5)

    def build_collision():
        builds.append("collision")
        return BoneCollision(rest, bones, reach=0.2, keep=0.5)

    items = (("rest", rest), ("reach", 0.2))
    made = [cached(tmp_path, "skullguard", items, build_guard), cached(tmp_path, "collision", items, build_collision)]
    back = [cached(tmp_path, "skullguard", items, build_guard), cached(tmp_path, "collision", items, build_collision)]
    assert builds == ["guard", "collision"]            # the second pair was read back
    for a, b in zip(made, back):
        assert type(a) is type(b) and a is not b
        assert_same(vars(a), vars(b))
    pushed = rest * 0.9                                   # the skin sunk into the bones
    moved = []
    for guard, collision in (made, back):
        p, q = pushed.copy(), pushed.copy()
        n = guard.apply(p, {k: v[0] for k, v in bones.items()})
        m = collision.apply(q, {})
        moved.append((n, m, p.tobytes(), q.tobytes()))
    assert moved[0][0] > 0 and moved[0][1] > 0
    assert moved[0] == moved[1]
    assert cached(None, "skullguard", items, build_guard) is not None and builds[-1] == "guard"
