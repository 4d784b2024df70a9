"""Binary glTF 2.0 (.glb) with the animation as morph targets, written with numpy + json.

Layout (one mesh, one node, one animation):

* the base mesh is frame 0: ``POSITION`` (float32) and ``indices`` (uint32 triangles;
  quads and n-gons are fan-triangulated, vertex order unchanged);
* morph target ``k - 1`` holds ``frame k - frame 0`` for k = 1 .. n_frames - 1, named
  ``frame_0002`` ... in ``mesh.extras.targetNames`` (Blender names the shape keys so);
* the animation drives the node's ``weights`` with LINEAR interpolation at times
  ``k / fps``: all zeros at frame 0 and one-hot on target ``k - 1`` at frame k, so a player
  shows exactly frame k at time k / fps and blends neighbouring frames in between.

Blender's glTF importer reads this as shape keys with an animated value per key. glTF is
+Y up with the model facing +Z, the project's own convention, and Blender converts it to
Z-up on import, so the head comes in upright with no options. A single-frame animation
is written as a static mesh.

Deltas are float32; each is nudged by at most one ulp so that ``base + delta`` rounds to
the frame's float32 position wherever that is possible (then the round trip is exact).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from .export_common import (
    ExportError,
    atomic_write_bytes,
    faces_to_csr,
    read_bytes,
    register_exporter,
    triangulate,
    validate_animation,
)

_GLB_MAGIC = 0x46546C67  # "glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def _exact_deltas(base: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """float32 deltas ``d`` with ``float32(base + d) == frames`` wherever one ulp of nudging finds it."""
    delta = (frames.astype(np.float64) - base.astype(np.float64)).astype(np.float32)
    for direction in (np.inf, -np.inf):
        wrong = (base + delta) != frames
        if not wrong.any():
            break
        nudged = np.nextafter(delta, np.float32(direction))
        delta = np.where(wrong & ((base + nudged) == frames), nudged, delta)
    return delta


class _Buffer:
    """Collects 4-byte aligned buffer views and their accessors."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.offset = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: np.ndarray, target: int | None = None, stride: int | None = None) -> int:
        blob = data.tobytes()
        view = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(blob)}
        if target is not None:
            view["target"] = target
        if stride is not None:
            view["byteStride"] = stride
        self.views.append(view)
        pad = (-len(blob)) % 4
        self.blobs.append(blob + b"\0" * pad)
        self.offset += len(blob) + pad
        return len(self.views) - 1

    def accessor(
        self, view: int, array: np.ndarray, kind: str, ctype: int, offset: int = 0, bounds: bool = False
    ) -> int:
        count = array.shape[0]
        accessor = {"bufferView": view, "byteOffset": offset, "componentType": ctype, "count": count, "type": kind}
        if bounds:
            flat = array.reshape(count, -1)
            accessor["min"] = [float(x) for x in flat.min(axis=0)]
            accessor["max"] = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1


def write_glb(path: str | Path, frames: object, faces: object, fps: float, *, name: str = "faceforge") -> Path:
    """Write the animation as a binary glTF with morph targets and a weights animation.

    Parameters
    ----------
    path : path ending in ``.glb``
    frames : (n_frames, n_verts, 3) float
        Positions per frame, model units (stored as float32, +Y up).
    faces : (m, k) int array or sequence of int sequences
        0-based; polygons are fan-triangulated.
    fps : float
        Key times are ``k / fps`` seconds.
    name : str
        Node, mesh and animation name.

    Returns
    -------
    Path
    """
    data = validate_animation(frames, fps)
    triangles = triangulate(*faces_to_csr(faces, data.shape[1])).astype(np.uint32)
    if triangles.shape[0] == 0:
        raise ValueError("a glTF mesh needs at least one face")
    base = data[0]
    n_frames, n_verts = data.shape[:2]
    buf = _Buffer()
    index_view = buf.view(triangles.ravel(), _ELEMENT_ARRAY_BUFFER)
    index_acc = buf.accessor(index_view, triangles.ravel(), "SCALAR", _UINT)
    base_acc = buf.accessor(buf.view(base, _ARRAY_BUFFER), base, "VEC3", _FLOAT, bounds=True)
    primitive: dict = {"attributes": {"POSITION": base_acc}, "indices": index_acc, "mode": 4}
    mesh: dict = {"name": name, "primitives": [primitive]}
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "faceforge"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": name, "mesh": 0}],
        "meshes": [mesh],
    }
    n_targets = n_frames - 1
    if n_targets:
        deltas = _exact_deltas(base[None], data[1:])
        target_view = buf.view(deltas, _ARRAY_BUFFER, stride=12)
        primitive["targets"] = [
            {"POSITION": buf.accessor(target_view, deltas[k], "VEC3", _FLOAT, offset=k * n_verts * 12, bounds=True)}
            for k in range(n_targets)
        ]
        mesh["weights"] = [0.0] * n_targets
        mesh["extras"] = {"targetNames": [f"frame_{k + 2:04d}" for k in range(n_targets)]}
        weights = np.zeros((n_frames, n_targets), dtype=np.float32)
        weights[np.arange(1, n_frames), np.arange(n_targets)] = 1.0
        gltf["animations"] = [weights_animation(buf, weights, fps, name)]
    return write_glb_document(path, gltf, buf)


def weights_animation(buf: "_Buffer", weights: np.ndarray, fps: float, name: str) -> dict:
    """A glTF animation of node 0's morph weights: ``weights`` (F, k) float32, frame ``f`` at
    ``f / fps`` seconds, linear between frames. Adds the time and weight accessors to ``buf``."""
    times = (np.arange(len(weights)) / float(fps)).astype(np.float32)
    time_acc = buf.accessor(buf.view(times), times, "SCALAR", _FLOAT, bounds=True)
    flat = np.ascontiguousarray(weights, dtype=np.float32).ravel()
    weight_acc = buf.accessor(buf.view(flat), flat, "SCALAR", _FLOAT)
    return {
        "name": name,
        "samplers": [{"input": time_acc, "output": weight_acc, "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
    }


def write_glb_document(path, gltf: dict, buf: "_Buffer") -> Path:
    """Write ``gltf`` (the JSON document, without its buffer lists) and ``buf``'s binary chunk as
    one GLB file, atomically (:func:`~faceforge.io.export_common.atomic_write_bytes`)."""
    gltf["buffers"] = [{"byteLength": buf.offset}]
    gltf["bufferViews"] = buf.views
    gltf["accessors"] = buf.accessors
    text = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    text += b" " * ((-len(text)) % 4)
    total = 12 + 8 + len(text) + 8 + buf.offset
    head = struct.pack("<III", _GLB_MAGIC, 2, total) + struct.pack("<II", len(text), _CHUNK_JSON)
    return atomic_write_bytes(path, [head, text, struct.pack("<II", buf.offset, _CHUNK_BIN), *buf.blobs])


def _read_accessor(gltf: dict, binary: bytes, index: int) -> np.ndarray:
    accessor = gltf["accessors"][index]
    view = gltf["bufferViews"][accessor["bufferView"]]
    dtype = {_FLOAT: "<f4", _UINT: "<u4"}[accessor["componentType"]]
    width = {"SCALAR": 1, "VEC3": 3}[accessor["type"]]
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    stride = view.get("byteStride", 4 * width)
    count = accessor["count"]
    if stride != 4 * width:
        raise ValueError("interleaved accessors are not read")
    array = np.frombuffer(binary, dtype=dtype, count=count * width, offset=start)
    return array.reshape(count, width) if width > 1 else array.copy()


def parse_glb(path: str | Path) -> tuple[dict, bytes]:
    """Split a GLB file into its JSON document and binary chunk (structure checked)."""
    raw = read_bytes(path, "glTF binary")
    if len(raw) < 20:
        raise ExportError("not a GLB file (too short)", path)
    magic, version, total = struct.unpack_from("<III", raw, 0)
    if magic != _GLB_MAGIC or version != 2 or total != len(raw):
        raise ExportError("not a glTF 2.0 binary (bad magic, version or length)", path)
    json_len, json_type = struct.unpack_from("<II", raw, 12)
    if json_type != _CHUNK_JSON:
        raise ExportError("first GLB chunk is not JSON", path)
    gltf = json.loads(raw[20 : 20 + json_len])
    binary = b""
    if 20 + json_len < len(raw):
        bin_len, bin_type = struct.unpack_from("<II", raw, 20 + json_len)
        if bin_type != _CHUNK_BIN:
            raise ExportError("second GLB chunk is not BIN", path)
        binary = raw[28 + json_len : 28 + json_len + bin_len]
    return gltf, binary


def read_glb(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Play back a GLB written by :func:`write_glb` at its key times.

    Returns
    -------
    frames : (n_keys, n_verts, 3) float32
        ``base + sum_j weight_j * target_j`` evaluated in float32 at each key (what a
        player shows); one frame for a static mesh.
    triangles : (t, 3) int64
    times : (n_keys,) float32, seconds
    """
    gltf, binary = parse_glb(path)
    primitive = gltf["meshes"][0]["primitives"][0]
    base = _read_accessor(gltf, binary, primitive["attributes"]["POSITION"])
    triangles = _read_accessor(gltf, binary, primitive["indices"]).reshape(-1, 3).astype(np.int64)
    targets = [_read_accessor(gltf, binary, t["POSITION"]) for t in primitive.get("targets", [])]
    if not targets:
        return base[None].copy(), triangles, np.zeros(1, dtype=np.float32)
    sampler = gltf["animations"][0]["samplers"][0]
    times = _read_accessor(gltf, binary, sampler["input"])
    weights = _read_accessor(gltf, binary, sampler["output"]).reshape(times.size, len(targets))
    frames = np.empty((times.size, *base.shape), dtype=np.float32)
    for k in range(times.size):
        frame = base.copy()
        for j in np.flatnonzero(weights[k]):
            frame += weights[k, j] * targets[j]
        frames[k] = frame
    return frames, triangles, times


register_exporter(".glb", write_glb)
