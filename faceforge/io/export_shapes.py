"""Named blendshapes (issue 27): a binary glTF with one morph target per shape, a USD stage with
``UsdSkelBlendShape``s, and a reader for the glTF.

glTF layout (one mesh, one node): the user's neutral mesh in the user's vertex order
(``POSITION``, area-weighted vertex ``NORMAL``s, ``TEXCOORD_0`` when the input has one UV per
vertex; polygons fan-triangulated), one morph target per shape holding ``shape - neutral``
(float32, nudged as :mod:`faceforge.io.export_gltf` does so that ``neutral + delta`` rounds to the
shape), named in ``mesh.extras.targetNames`` (Blender's importer names the shape keys so, the neutral
becomes ``Basis``; three.js fills ``morphTargetDictionary`` from it). With ``weights (F, k)`` an
animation drives the node's ``weights`` at ``t = f / fps`` (LINEAR).

USD layout: ``/Head`` (SkelRoot) holds the ``Mesh`` ``face`` with one ``BlendShape`` child per
shape (``offsets`` and ``pointIndices`` of the vertices it moves) and, with weights, a
``Skeleton`` ``skel`` bound to the mesh whose ``SkelAnimation`` ``anim`` carries the
``blendShapeWeights`` time samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .export_common import ExportError, atomic_write_bytes, faces_to_csr, triangulate
from .export_gltf import _ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _FLOAT, _UINT
from .export_gltf import _Buffer, _exact_deltas, _read_accessor, parse_glb, weights_animation, write_glb_document


def _vertex_normals(v: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Unit area-weighted normals (n, 3) float32; +Y for a vertex no face uses (or of zero area)."""
    from faceforge.geometry.triangles import vertex_normals

    n = np.asarray(vertex_normals(v.astype(np.float64), tri.astype(np.int64)), dtype=np.float64)
    length = np.linalg.norm(n, axis=1)
    bad = ~(length > 1e-20)
    n[bad] = (0.0, 1.0, 0.0)
    length[bad] = 1.0
    return (n / length[:, None]).astype(np.float32)


def _check(base, shapes, names, weights):
    base = np.ascontiguousarray(base, dtype=np.float32)
    shapes = np.ascontiguousarray(shapes, dtype=np.float32)
    if base.ndim != 2 or base.shape[1] != 3 or shapes.shape[1:] != base.shape:
        raise ValueError(f"base must be (n, 3) and shapes (k, n, 3), got {base.shape} and {shapes.shape}")
    if len(names) != len(shapes) or len(set(names)) != len(names):
        raise ValueError("names must be unique, one per shape")
    if not (np.isfinite(base).all() and np.isfinite(shapes).all()):
        raise ValueError("non-finite vertex positions")
    if weights is not None:
        weights = np.ascontiguousarray(weights, dtype=np.float32)
        if weights.ndim != 2 or weights.shape[1] != len(shapes) or not len(weights):
            raise ValueError(f"weights must be (F >= 1, {len(shapes)}), got {weights.shape}")
    return base, shapes, weights


def write_shapes_glb(path, base, shapes, names, faces, *, uvs=None, weights=None, fps: float = 25.0,
                     name: str = "faceforge", not_made=()) -> Path:
    """Write the neutral mesh with named morph targets (module docstring).

    base : (n, 3) float neutral positions; shapes : (k, n, 3) float positions of each shape;
    names : k str; faces : (m, k) int or polygons; uvs : (n, 2) float or None (OBJ convention,
    v up: written as glTF's 1 - v); weights : (F, k) float or None, an animation at ``fps``;
    not_made : names of shapes that are placeholders (listed in ``mesh.extras.notMade``).
    """
    base, shapes, weights = _check(base, shapes, names, weights)
    tri = triangulate(*faces_to_csr(faces, len(base))).astype(np.uint32)
    if not len(tri):
        raise ValueError("a glTF mesh needs at least one face")
    buf = _Buffer()
    index_acc = buf.accessor(buf.view(tri.ravel(), _ELEMENT_ARRAY_BUFFER), tri.ravel(), "SCALAR", _UINT)
    attrs = {"POSITION": buf.accessor(buf.view(base, _ARRAY_BUFFER), base, "VEC3", _FLOAT, bounds=True)}
    normals = _vertex_normals(base, tri)
    attrs["NORMAL"] = buf.accessor(buf.view(normals, _ARRAY_BUFFER), normals, "VEC3", _FLOAT)
    if uvs is not None:
        uv = np.ascontiguousarray(uvs, dtype=np.float32).copy()
        if uv.shape != (len(base), 2):
            raise ValueError(f"uvs must be ({len(base)}, 2), got {uv.shape}")
        uv[:, 1] = 1.0 - uv[:, 1]
        attrs["TEXCOORD_0"] = buf.accessor(buf.view(uv, _ARRAY_BUFFER), uv, "VEC2", _FLOAT)
    primitive = {"attributes": attrs, "indices": index_acc, "mode": 4}
    mesh = {"name": name, "primitives": [primitive]}
    gltf = {"asset": {"version": "2.0", "generator": "faceforge bake"}, "scene": 0,
            "scenes": [{"nodes": [0]}], "nodes": [{"name": name, "mesh": 0}], "meshes": [mesh]}
    if len(shapes):
        deltas = _exact_deltas(base[None], shapes)
        view = buf.view(deltas, _ARRAY_BUFFER, stride=12)
        n = len(base)
        primitive["targets"] = [{"POSITION": buf.accessor(view, deltas[k], "VEC3", _FLOAT, offset=k * n * 12,
                                                          bounds=True)} for k in range(len(shapes))]
        mesh["weights"] = [0.0] * len(shapes)
        mesh["extras"] = {"targetNames": list(map(str, names))}
        if len(not_made):
            mesh["extras"]["notMade"] = [str(n) for n in not_made]
        if weights is not None:
            gltf["animations"] = [weights_animation(buf, weights, fps, "weights")]
    return write_glb_document(path, gltf, buf)


def read_shapes_glb(path) -> dict:
    """Read a GLB written by :func:`write_shapes_glb`: ``{"base" (n, 3), "targets" (k, n, 3) deltas,
    "names" [k], "normals" (n, 3) or None, "uvs" (n, 2) (glTF convention) or None, "triangles"
    (t, 3), "times" (F,) and "weights" (F, k) or None}`` (float32)."""
    gltf, binary = parse_glb(path)
    mesh = gltf["meshes"][0]
    prim = mesh["primitives"][0]
    attrs = prim["attributes"]
    out = {"base": _read_accessor(gltf, binary, attrs["POSITION"]),
           "normals": _read_accessor(gltf, binary, attrs["NORMAL"]) if "NORMAL" in attrs else None,
           "uvs": _read_vec2(gltf, binary, attrs["TEXCOORD_0"]) if "TEXCOORD_0" in attrs else None,
           "triangles": _read_accessor(gltf, binary, prim["indices"]).reshape(-1, 3).astype(np.int64),
           "names": list((mesh.get("extras") or {}).get("targetNames", [])), "times": None, "weights": None}
    targets = [_read_accessor(gltf, binary, t["POSITION"]) for t in prim.get("targets", [])]
    out["targets"] = np.stack(targets) if targets else np.zeros((0,) + out["base"].shape, np.float32)
    if gltf.get("animations"):
        s = gltf["animations"][0]["samplers"][0]
        out["times"] = _read_accessor(gltf, binary, s["input"])
        out["weights"] = _read_accessor(gltf, binary, s["output"]).reshape(len(out["times"]), len(targets))
    return out


def _read_vec2(gltf, binary, index) -> np.ndarray:
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(binary, "<f4", count=2 * acc["count"], offset=start).reshape(-1, 2).copy()


def read_obj_uvs(path, n_verts: int):
    """Per-vertex UVs (n, 2) float of an OBJ whose every vertex has one texture coordinate in all
    its corners (``f v/vt ...``), else None (no ``vt``, or a seam: a vertex with two UVs; the
    glTF keeps the user's vertices, so it cannot split them)."""
    path = Path(path)
    if path.suffix.lower() != ".obj":
        return None
    vts, uv, seen = [], np.full((n_verts, 2), np.nan), np.zeros(n_verts, bool)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    for line in lines:
        if line.startswith("vt "):
            vts.append([float(x) for x in line.split()[1:3]])
        elif line.startswith("f ") and vts:
            for corner in line.split()[1:]:
                parts = corner.split("/")
                if len(parts) < 2 or not parts[1]:
                    return None
                vi, ti = int(parts[0]), int(parts[1])
                vi = vi - 1 if vi > 0 else n_verts + vi
                ti = ti - 1 if ti > 0 else len(vts) + ti
                t = vts[ti]
                if seen[vi] and (uv[vi] != t).any():
                    return None
                uv[vi], seen[vi] = t, True
    if not vts or not seen.any():
        return None
    uv[~seen] = 0.0
    return uv


def write_shapes_usda(path, base, shapes, names, faces, *, weights=None, fps: float = 25.0,
                      up_axis: str = "Y", eps: float = 0.0) -> Path:
    """USD text with ``UsdSkelBlendShape``s (module docstring). Offsets are ``shape - base``
    for the vertices that move more than ``eps`` (every vertex for eps = 0 that moves at all).
    base (n, 3); shapes (k, n, 3); names k valid USD identifiers; weights (F, k) or None."""
    from .export_usd import _fps, _ints, _points

    base, shapes, weights = _check(base, shapes, names, weights)
    counts, indices = _polygons(faces, len(base))
    bad = [n for n in names if not (n[:1].isalpha() or n[:1] == "_") or not n.replace("_", "a").isalnum()]
    if bad:
        raise ValueError(f"{bad[0]!r} is not a USD identifier")
    lines = ["#usda 1.0", "(", '    defaultPrim = "Head"', "    metersPerUnit = 1", f'    upAxis = "{up_axis}"']
    if weights is not None:
        lines += ["    startTimeCode = 0", f"    endTimeCode = {len(weights) - 1}",
                  f"    timeCodesPerSecond = {_fps(fps)}", f"    framesPerSecond = {_fps(fps)}"]
    lines += [")", "", 'def SkelRoot "Head" (', '    prepend apiSchemas = ["SkelBindingAPI"]', ")", "{",
              '    def Mesh "face" (', '        prepend apiSchemas = ["SkelBindingAPI"]', "    )", "    {",
              f"        int[] faceVertexCounts = {_ints(counts)}",
              f"        int[] faceVertexIndices = {_ints(indices)}",
              f"        point3f[] points = {_points(base)}",
              '        uniform token subdivisionScheme = "none"',
              "        uniform token[] skel:blendShapes = [" + ", ".join(f'"{n}"' for n in names) + "]",
              "        rel skel:blendShapeTargets = [" + ", ".join(f"</Head/face/{n}>" for n in names) + "]",
              "        rel skel:skeleton = </Head/skel>"]
    for n, shape in zip(names, shapes):
        d = shape.astype(np.float64) - base.astype(np.float64)
        idx = np.flatnonzero(np.linalg.norm(d, axis=1) > eps)
        if not len(idx):
            idx = np.zeros(1, dtype=np.int64)   # an empty shape keeps one zero offset (importers skip none)
        lines += ["", f'        def BlendShape "{n}"', "        {",
                  f"            uniform vector3f[] offsets = {_points(d[idx])}",
                  f"            uniform int[] pointIndices = {_ints(idx)}", "        }"]
    lines += ["    }", "", '    def Skeleton "skel" (', '        prepend apiSchemas = ["SkelBindingAPI"]', "    )",
              "    {", "        uniform token[] joints = []", "        uniform matrix4d[] bindTransforms = []",
              "        uniform matrix4d[] restTransforms = []"]
    if weights is not None:
        lines += ["        rel skel:animationSource = </Head/skel/anim>", "", '        def SkelAnimation "anim"',
                  "        {", "            uniform token[] blendShapes = [" + ", ".join(f'"{n}"' for n in names) + "]",
                  "            float[] blendShapeWeights.timeSamples = {"]
        lines += [f"                {f}: [" + ", ".join(f"{x:.6g}" for x in w) + "]," for f, w in enumerate(weights)]
        lines += ["            }", "        }"]
    lines += ["    }", "}", ""]
    return atomic_write_bytes(path, "\n".join(lines).encode("utf-8"))


def _polygons(faces, n_verts):
    idx, starts = faces_to_csr(faces, n_verts)
    return np.diff(starts), idx


__all__ = ["ExportError", "read_obj_uvs", "read_shapes_glb", "write_shapes_glb", "write_shapes_usda"]
