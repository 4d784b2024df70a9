"""Animation exporters: exact round trips, file structure, registry, atomic writes."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from faceforge.io.export import (
    EXPORTERS,
    ExportError,
    export_animation,
    exporter_for,
    parse_glb,
    read_glb,
    read_mdd,
    read_obj_sequence,
    read_pc2,
    write_glb,
    write_mdd,
    write_obj_sequence,
    write_pc2,
)
from faceforge.io.export_common import atomic_write_bytes, faces_to_csr, polygons_from_fan, triangulate

MAKEHUMAN = Path(__file__).resolve().parents[2] / "samples" / "makehuman" / "mh_head_default.obj"


def animation(n_frames=6, seed=0):
    """A small mixed mesh (quads, triangles, a pentagon) with vertices moving per frame."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="xy"), -1).reshape(-1, 2)
    rest = np.column_stack([grid, np.zeros(len(grid))]) * 1.7 - np.array([2.0, 1.0, 0.0])
    faces = [(0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7), (2, 7, 6), (4, 5, 9, 8), (5, 6, 10, 9), (6, 7, 11, 10)]
    faces += [(0, 4, 8, 3, 11)]  # a pentagon (self-overlapping is fine for storage)
    frames = rest[None] + rng.normal(scale=0.05, size=(n_frames, len(rest), 3)).cumsum(axis=0)
    return frames, faces


def read_obj(path: Path):
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        tokens = line.split()
        if tokens and tokens[0] == "v":
            vertices.append([float(t) for t in tokens[1:4]])
        elif tokens and tokens[0] == "f":
            faces.append(tuple(int(t.split("/")[0]) - 1 for t in tokens[1:]))
    return np.array(vertices), faces


# ----------------------------------------------------------------- round trips


def test_pc2_round_trip_and_header(tmp_path):
    frames, faces = animation()
    path = write_pc2(tmp_path / "a.pc2", frames, faces, 25.0)
    back, start, sampling = read_pc2(path)
    np.testing.assert_array_equal(back, frames.astype(np.float32))
    raw = path.read_bytes()
    assert raw[:12] == b"POINTCACHE2\0"
    assert struct.unpack("<iiffi", raw[12:32]) == (1, 12, 0.0, 1.0, 6)
    assert (start, sampling) == (0.0, 1.0) and len(raw) == 32 + 6 * 12 * 12
    assert struct.unpack("<3f", raw[32:44]) == tuple(frames[0, 0].astype(np.float32))


def test_mdd_round_trip_is_big_endian_with_times(tmp_path):
    frames, faces = animation(n_frames=5)
    path = write_mdd(tmp_path / "a.mdd", frames, faces, 24.0)
    back, times = read_mdd(path)
    np.testing.assert_array_equal(back, frames.astype(np.float32))
    np.testing.assert_array_equal(times, (np.arange(5) / 24.0).astype(np.float32))
    raw = path.read_bytes()
    assert struct.unpack(">ii", raw[:8]) == (5, 12) and len(raw) == 8 + 5 * 4 + 5 * 12 * 12
    assert struct.unpack(">3f", raw[28:40]) == tuple(frames[0, 0].astype(np.float32))


def test_obj_sequence_keeps_faces_and_order(tmp_path):
    frames, faces = animation(n_frames=3)
    folder = write_obj_sequence(tmp_path / "take", frames, faces, 30.0)
    assert sorted(p.name for p in folder.iterdir()) == ["take_0001.obj", "take_0002.obj", "take_0003.obj"]
    back, back_faces = read_obj_sequence(folder)
    np.testing.assert_array_equal(back, frames.astype(np.float32))
    assert back_faces == faces


def test_obj_sequence_of_a_real_quad_mesh(tmp_path):
    vertices, faces = read_obj(MAKEHUMAN)
    frames = np.stack([vertices, vertices * 1.01])
    folder = write_obj_sequence(tmp_path / "mh", frames, faces, 25.0)
    again, again_faces = read_obj(folder / "mh_0002.obj")
    assert again_faces == faces and all(len(f) == 4 for f in again_faces)
    np.testing.assert_array_equal(again.astype(np.float32), frames[1].astype(np.float32))


def _ulp_bound(frames32):
    """Two float32 ulps of the larger of the base position and the frame's position."""
    scale = np.maximum(np.abs(frames32), np.abs(frames32[:1]))
    return 2 * np.spacing(scale)


def test_glb_plays_back_every_frame(tmp_path):
    frames, faces = animation(n_frames=7)
    path = write_glb(tmp_path / "a.glb", frames, faces, 25.0)
    back, triangles, times = read_glb(path)
    f32 = frames.astype(np.float32)
    assert np.all(np.abs(back - f32) <= _ulp_bound(f32))
    # exact wherever float32 can hold the delta exactly (Sterbenz: base and frame within 2x)
    base = f32[:1]
    sterbenz = (np.sign(base) == np.sign(f32)) & (np.abs(base) / 2 <= np.abs(f32)) & (np.abs(f32) <= 2 * np.abs(base))
    assert sterbenz.mean() > 0.5
    np.testing.assert_array_equal(back[sterbenz], f32[sterbenz])
    np.testing.assert_array_equal(times, (np.arange(7) / 25.0).astype(np.float32))
    np.testing.assert_array_equal(triangles, triangulate(*faces_to_csr(faces, 12)))


def test_glb_structure_read_by_pygltflib(tmp_path):
    pygltflib = pytest.importorskip("pygltflib")
    frames, faces = animation(n_frames=5)
    path = write_glb(tmp_path / "a.glb", frames, faces, 25.0)
    gltf = pygltflib.GLTF2().load(str(path))
    assert gltf.asset.version == "2.0" and len(gltf.meshes) == 1 and gltf.nodes[0].mesh == 0
    primitive = gltf.meshes[0].primitives[0]
    assert len(primitive.targets) == 4 and gltf.meshes[0].weights == [0.0] * 4
    assert gltf.meshes[0].extras["targetNames"] == ["frame_0002", "frame_0003", "frame_0004", "frame_0005"]
    base = gltf.accessors[primitive.attributes.POSITION]
    assert base.count == 12 and base.min == frames[0].astype(np.float32).min(0).tolist()
    (channel,), (sampler,) = gltf.animations[0].channels, gltf.animations[0].samplers
    assert channel.target.path == "weights" and channel.target.node == 0
    assert sampler.interpolation == "LINEAR"
    assert gltf.accessors[sampler.input].count == 5 and gltf.accessors[sampler.output].count == 5 * 4
    assert gltf.accessors[sampler.input].max == [np.float32(4 / 25).item()]
    n_triangles = sum(len(f) - 2 for f in faces)
    assert gltf.accessors[primitive.indices].count == 3 * n_triangles
    binary = gltf.binary_blob()
    assert len(binary) >= gltf.buffers[0].byteLength
    for view in gltf.bufferViews:
        assert view.byteOffset % 4 == 0 and view.byteOffset + view.byteLength <= gltf.buffers[0].byteLength
    for t in primitive.targets:  # morph POSITION accessors carry bounds, as the spec requires
        accessor = gltf.accessors[t["POSITION"] if isinstance(t, dict) else t.POSITION]
        assert accessor.min is not None and accessor.max is not None


def test_glb_base_mesh_read_by_trimesh(tmp_path):
    """A second, independent reader sees frame 0 with the input's vertex order."""
    trimesh = pytest.importorskip("trimesh")
    frames, faces = animation(n_frames=3)
    scene = trimesh.load(write_glb(tmp_path / "a.glb", frames, faces, 25.0), process=False)
    (mesh,) = scene.geometry.values()
    np.testing.assert_array_equal(np.asarray(mesh.vertices, dtype=np.float32), frames[0].astype(np.float32))
    np.testing.assert_array_equal(mesh.faces, triangulate(*faces_to_csr(faces, 12)))


def test_point_caches_need_no_faces(tmp_path):
    frames, _ = animation(n_frames=2)
    f32 = frames.astype(np.float32)
    np.testing.assert_array_equal(read_pc2(write_pc2(tmp_path / "a.pc2", frames, None, 25.0))[0], f32)
    np.testing.assert_array_equal(read_mdd(write_mdd(tmp_path / "a.mdd", frames, None, 25.0))[0], f32)


def test_single_frame_glb_is_a_static_mesh(tmp_path):
    frames, faces = animation(n_frames=1)
    gltf, _ = parse_glb(write_glb(tmp_path / "s.glb", frames, faces, 25.0))
    assert "animations" not in gltf and "targets" not in gltf["meshes"][0]["primitives"][0]
    back, _, _ = read_glb(tmp_path / "s.glb")
    np.testing.assert_array_equal(back, frames.astype(np.float32))


# ----------------------------------------------------------------- faces and triangulation


def test_fan_triangulation_covers_each_convex_polygon():
    angles = np.linspace(0, 2 * np.pi, 7)[:-1]
    hexagon = np.column_stack([np.cos(angles), np.sin(angles) * 0.5, np.zeros(6)])
    vertices = np.vstack([hexagon, [[3, 0, 0], [4, 0, 0], [4, 1, 0], [3, 1, 0]]])
    faces = [tuple(range(6)), (6, 7, 8, 9)]
    tris = triangulate(*faces_to_csr(faces, len(vertices)))
    assert tris.shape == (4 + 2, 3)
    a, b, c = vertices[tris[:, 0]], vertices[tris[:, 1]], vertices[tris[:, 2]]
    areas = 0.5 * np.cross(b - a, c - a)[:, 2]
    assert np.all(areas > 0)  # orientation kept
    x, y = hexagon[:, 0], hexagon[:, 1]
    shoelace = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    assert areas[:4].sum() == pytest.approx(shoelace) and areas[4:].sum() == pytest.approx(1.0)
    assert set(tris[:4].ravel()) == set(range(6)) and set(tris[4:].ravel()) == {6, 7, 8, 9}


def test_polygons_from_fan_undoes_the_triangulation():
    _, faces = animation()
    indices, starts = faces_to_csr(faces, 12)
    triangles = triangulate(indices, starts)
    source = np.repeat(np.arange(len(faces)), np.diff(starts) - 2)
    assert polygons_from_fan(triangles, source) == faces
    with pytest.raises(ValueError, match="not a fan"):
        polygons_from_fan(triangles[:, [1, 0, 2]], source)
    with pytest.raises(ValueError, match="consecutive"):
        polygons_from_fan(triangles, source[::-1])


def test_polygons_from_fan_matches_the_mesh_loader():
    mesh = pytest.importorskip("faceforge.io.mesh")
    _, triangles, info = mesh.load_mesh(MAKEHUMAN)
    assert polygons_from_fan(triangles, info.face_source) == read_obj(MAKEHUMAN)[1]


def test_array_faces_and_list_faces_agree():
    faces = np.array([[0, 1, 2], [2, 1, 3]])
    a = faces_to_csr(faces, 4)
    b = faces_to_csr([list(f) for f in faces], 4)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


# ----------------------------------------------------------------- registry and errors


@pytest.mark.parametrize("name", ["a.pc2", "a.MDD", "a.glb", "folder"])
def test_export_dispatches_by_suffix(tmp_path, name):
    frames, faces = animation(n_frames=2)
    out = export_animation(tmp_path / name, frames, faces, 25.0)
    assert out.exists()
    assert exporter_for(tmp_path / name) is EXPORTERS[Path(name).suffix.lower()]


def test_unknown_suffix_lists_the_valid_ones(tmp_path):
    frames, faces = animation(n_frames=2)
    with pytest.raises(ExportError) as err:
        export_animation(tmp_path / "a.fbx", frames, faces, 25.0)
    message = str(err.value)
    assert "a.fbx" in message and "'.fbx'" in message
    for suffix in (".glb", ".mdd", ".pc2", "no suffix"):
        assert suffix in message


@pytest.mark.parametrize(
    "frames, faces, fps, match",
    [
        (np.zeros((2, 4, 2)), [(0, 1, 2)], 25.0, "shape"),
        (np.zeros((0, 4, 3)), [(0, 1, 2)], 25.0, "shape"),
        (np.full((2, 4, 3), np.nan), [(0, 1, 2)], 25.0, "finite"),
        (np.zeros((2, 4, 3)), [(0, 1, 4)], 25.0, r"\[0, 4\)"),
        (np.zeros((2, 4, 3)), [(0, 1)], 25.0, ">= 3"),
        (np.zeros((2, 4, 3)), [(0, 1, 2)], 0.0, "fps"),
    ],
)
@pytest.mark.parametrize("writer", [write_pc2, write_mdd, write_glb, write_obj_sequence])
def test_invalid_animations_are_rejected_before_writing(tmp_path, writer, frames, faces, fps, match):
    with pytest.raises(ValueError, match=match):
        writer(tmp_path / "out", frames, faces, fps)
    assert list(tmp_path.iterdir()) == []


def test_interrupted_write_keeps_the_old_file(tmp_path):
    path = tmp_path / "a.pc2"
    path.write_bytes(b"old")

    def chunks():
        yield b"new data"
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write_bytes(path, chunks())
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["a.pc2"]


def test_missing_folder_is_an_export_error(tmp_path):
    frames, faces = animation(n_frames=2)
    with pytest.raises(ExportError, match="cannot write here"):
        write_pc2(tmp_path / "no" / "a.pc2", frames, faces, 25.0)


def test_obj_sequence_replaces_only_an_earlier_sequence(tmp_path):
    frames, faces = animation(n_frames=4)
    write_obj_sequence(tmp_path / "take", frames, faces, 25.0)
    write_obj_sequence(tmp_path / "take", frames[:2], faces, 25.0)
    assert sorted(p.name for p in (tmp_path / "take").iterdir()) == ["take_0001.obj", "take_0002.obj"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take"]  # no staging leftovers
    (tmp_path / "take" / "notes.txt").write_text("mine")
    with pytest.raises(ExportError, match="other files"):
        write_obj_sequence(tmp_path / "take", frames, faces, 25.0)
    assert (tmp_path / "take" / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("reader, payload", [(read_pc2, b"POINTCACHE2\0" + b"\0" * 10), (read_mdd, b"\0\0\0\1")])
def test_readers_reject_broken_caches(tmp_path, reader, payload):
    path = tmp_path / "broken"
    path.write_bytes(payload)
    with pytest.raises(ExportError, match="broken"):
        reader(path)


def test_obj_sequence_folder_and_files_get_the_umask_mode(tmp_path):
    """mkdtemp's staging folder was renamed into place as 0o700: nobody else could open the frames."""
    import os

    frames, faces = animation(n_frames=2)
    old = os.umask(0o022)
    try:
        folder = write_obj_sequence(tmp_path / "take", frames, faces, 25.0)
        made = tmp_path / "plain"
        made.mkdir()
    finally:
        os.umask(old)
    assert folder.stat().st_mode & 0o777 == made.stat().st_mode & 0o777 == 0o755
    assert {p.stat().st_mode & 0o777 for p in folder.iterdir()} == {0o644}


def test_unused_vertices_and_the_blender_notes_name_them(tmp_path):
    """Blender 4.5's OBJ and glTF importers drop vertices no face uses (tests/test_blender.py);
    the export notes say so, per format, and stay silent for a mesh without such vertices."""
    from faceforge.io.export import blender_notes
    from faceforge.io.export_common import unused_vertices

    frames, faces = animation(n_frames=2)
    assert unused_vertices(faces, 12).size == 0
    assert blender_notes("a.pc2", faces, 12) == [] and blender_notes("a.glb", np.array(faces[:2]), 12) != []
    np.testing.assert_array_equal(unused_vertices([(0, 1, 5, 4), (2, 3, 7)], 12), [6, 8, 9, 10, 11])
    cache, = blender_notes(tmp_path / "a.MDD", [(0, 2, 3)], 4)
    assert cache.startswith("1 vertex (first: index 1) used by no face") and "Vertex count mismatch" in cache
    mesh, = blender_notes(tmp_path / "take", [(0, 1, 2)], 6)
    assert mesh.startswith("3 vertices (first: index 3)") and "after index 3" in mesh
