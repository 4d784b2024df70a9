"""Read and write surface meshes, keeping the user's vertex order.

``load_mesh(path) -> (vertices (n, 3) float64, faces (m, 3) int64, MeshInfo)``.
Polygons are fan-triangulated and ``MeshInfo.face_source[t]`` is the index (in
file order) of the polygon that triangle ``t`` came from. Readers, by extension:

=========  ==============================================================
.obj       own reader (vertex order and polygon order exactly as written)
.off       own reader
.ply       meshio (ASCII and binary; mixed polygon runs kept in order)
.stl       trimesh; STL stores a triangle soup, so coincident vertices are merged
.glb/.gltf trimesh, every primitive concatenated (process=False)
.vtk/.vtu  meshio (triangle, quad and polygon cells)
=========  ==============================================================

Every failure is a :class:`~faceforge.exceptions.MeshError` naming the file:
missing or unreadable file, unsupported format (the message lists the supported
ones), a mesh without faces, NaN/inf coordinates, out-of-range indices.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from faceforge.exceptions import MeshError


@dataclass(frozen=True)
class MeshInfo:
    """Where a mesh came from.

    Attributes
    ----------
    path : the file read.
    format : extension without dot (``"obj"``).
    n_polygons : polygons in the file (before triangulation).
    face_source : (m,) int64, polygon index of each triangle.
    """

    path: str
    format: str
    n_polygons: int
    face_source: np.ndarray

    @property
    def triangulated(self) -> bool:
        """True when some polygon had more than three corners."""
        return self.n_polygons != len(self.face_source)


# ---------------------------------------------------------------------------
# polygons -> triangles


def triangulate_polygons(polygons: list, path: str = "<mesh>") -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons given as index sequences.

    Returns ``faces (m, 3) int64`` and ``face_source (m,) int64`` (polygon of each
    triangle); a polygon of k >= 3 corners gives k - 2 triangles (c0, ci, ci+1).
    """
    sizes = np.fromiter((len(p) for p in polygons), dtype=np.int64, count=len(polygons))
    if len(sizes) and sizes.min() < 3:
        bad = int(np.argmin(sizes))
        raise MeshError(f"polygon {bad} has {sizes[bad]} corners, at least 3 are needed", path)
    if len(sizes) and sizes.max() == sizes.min():  # uniform: vectorized
        corners = np.asarray(polygons, dtype=np.int64).reshape(len(polygons), -1)
        k = corners.shape[1]
        fan = np.stack([np.zeros(k - 2, np.int64), np.arange(1, k - 1), np.arange(2, k)], axis=1)
        faces = corners[:, fan].reshape(-1, 3)
        source = np.repeat(np.arange(len(polygons), dtype=np.int64), k - 2)
        return faces, source
    faces, source = [], []
    for index, polygon in enumerate(polygons):
        for i in range(1, len(polygon) - 1):
            faces.append((polygon[0], polygon[i], polygon[i + 1]))
            source.append(index)
    return np.asarray(faces, dtype=np.int64).reshape(-1, 3), np.asarray(source, dtype=np.int64)


# ---------------------------------------------------------------------------
# readers: each returns (vertices, polygons list or faces array)


def _one_line(text: str, limit: int = 160) -> str:
    """First line of a library's error message, without control characters, shortened."""
    line = (text.strip().splitlines() or [""])[0]
    line = "".join(ch if ch.isprintable() else "?" for ch in line)
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise MeshError(f"cannot read: {exc.strerror}", path) from None


def _read_obj_fast(text: str):
    """The common OBJ in bulk (numpy): every ``v`` line x y z, every ``f`` line three
    positive corner indices (``i``, ``i/t``, ``i/t/n`` or ``i//n``). Returns ``(vertices
    (n, 3), faces (m, 3) int64)``, or None for anything else (the line-by-line reader then
    reads it and names a bad line): a 45k-vertex head in about a fifth of the time."""
    import re

    if re.search(r"^[ \t]+[vf][ \t]", text, re.M):
        return None                                   # indented lines: the careful reader
    v = re.findall(r"^v[ \t]+(.*)$", text, re.M)
    f = re.findall(r"^f[ \t]+(.*)$", text, re.M)
    try:
        vertices = np.array(" ".join(v).split(), dtype=np.float64)
        corners = np.array(re.sub(r"/\S*", "", " ".join(f)).split(), dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    if len(vertices) != 3 * len(v) or len(corners) != 3 * len(f):
        return None                                   # w coordinates, colours, polygons, short lines
    if len(corners) and (corners.min() < 1 or not np.isfinite(vertices).all()):
        return None
    return vertices.reshape(-1, 3), corners.reshape(-1, 3) - 1


def _read_obj(path: Path):
    text = _read_text(path)
    fast = _read_obj_fast(text)
    return fast if fast is not None else _obj_polygons(text, path)


def read_obj_polygons(path: str | Path) -> tuple[np.ndarray, list[list[int]]]:
    """An OBJ's ``vertices (n, 3) float64`` and its polygons as they are in the file (lists of
    0-based corner indices, not triangulated: quads stay quads), for tools that edit a mesh's
    polygons; :class:`MeshError` naming the file and line of a malformed one."""
    path = Path(path)
    if not path.is_file():
        raise MeshError("mesh file not found", path)
    return _obj_polygons(_read_text(path), path)


def _obj_polygons(text: str, path: Path):
    vertices, polygons = [], []
    for number, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                vertices.append([float(x) for x in parts[1:4]])
                if len(vertices[-1]) != 3:
                    raise ValueError("a vertex needs x y z")
            elif parts[0] == "f":
                n = len(vertices)
                corners = []
                for token in parts[1:]:
                    index = int(token.split("/", 1)[0])
                    corners.append(index - 1 if index > 0 else n + index)
                if len(corners) < 3:
                    raise ValueError(f"a face needs at least 3 corners, got {len(corners)}")
                polygons.append(corners)
        except ValueError as exc:
            raise MeshError(f"malformed OBJ line: {exc}", path, number) from None
    return np.asarray(vertices, dtype=np.float64).reshape(-1, 3), polygons


def _read_off(path: Path):
    lines = [ln.split("#", 1)[0].split() for ln in _read_text(path).splitlines()]
    rows = [(i + 1, ln) for i, ln in enumerate(lines) if ln]
    try:
        if not rows or not rows[0][1][0].endswith("OFF"):
            raise ValueError("missing OFF header")
        header = rows[0][1][1:] or rows[1][1]
        start = 1 if rows[0][1][1:] else 2
        n_vertices, n_faces = int(header[0]), int(header[1])
        vertex_rows = rows[start:start + n_vertices]
        face_rows = rows[start + n_vertices:start + n_vertices + n_faces]
        if len(vertex_rows) < n_vertices or len(face_rows) < n_faces:
            raise ValueError(f"header announces {n_vertices} vertices and {n_faces} faces; file ends early")
        vertices = np.array([[float(x) for x in row[:3]] for _, row in vertex_rows], dtype=np.float64)
        polygons = []
        for number, row in face_rows:
            k = int(row[0])
            if len(row) < k + 1:
                raise ValueError(f"line {number}: face announces {k} corners")
            polygons.append([int(x) for x in row[1:k + 1]])
    except (ValueError, IndexError) as exc:
        raise MeshError(f"malformed OFF: {exc}", path) from None
    return vertices.reshape(-1, 3), polygons


def _read_meshio(path: Path):
    import contextlib
    import io

    import meshio

    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            mesh = meshio.read(path)
    except SystemExit:  # meshio's PLY reader calls sys.exit on malformed headers
        detail = _one_line(chatter.getvalue()) or "malformed file"
        raise MeshError(f"cannot read {path.suffix[1:].upper()}: {detail}", path) from None
    except Exception as exc:  # meshio raises many types for bad files
        raise MeshError(f"cannot read {path.suffix[1:].upper()}: {_one_line(str(exc)) or type(exc).__name__}", path) from None
    polygons = []
    for block in mesh.cells:
        if block.type in ("triangle", "quad", "polygon") or block.type.startswith("polygon"):
            polygons.extend(block.data.tolist())
    return np.asarray(mesh.points, dtype=np.float64)[:, :3].reshape(-1, 3), polygons


def _read_trimesh(path: Path, merge: bool):
    import trimesh

    try:
        with np.errstate(all="ignore"):  # NaN/inf input is reported by check_arrays instead
            mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise MeshError(f"cannot read {path.suffix[1:].upper()}: {_one_line(str(exc)) or type(exc).__name__}", path) from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError("no triangle mesh found in the file", path)
    if merge and len(mesh.faces) and np.isfinite(mesh.vertices).all():
        mesh.merge_vertices()
    return np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3), np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)


#: extension -> reader(path) -> (vertices, polygons list | faces array)
READERS: dict[str, Callable] = {
    ".obj": _read_obj,
    ".off": _read_off,
    ".ply": _read_meshio,
    ".vtk": _read_meshio,
    ".vtu": _read_meshio,
    ".stl": lambda p: _read_trimesh(p, merge=True),
    ".glb": lambda p: _read_trimesh(p, merge=False),
    ".gltf": lambda p: _read_trimesh(p, merge=False),
}


def supported_formats() -> list[str]:
    return sorted(READERS)


def load_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray, MeshInfo]:
    """Read a surface mesh; see the module docstring for formats and errors.

    Returns
    -------
    vertices : (n, 3) float64, in the file's order and units.
    faces : (m, 3) int64, counter-clockwise as in the file, polygons fan-triangulated.
    info : :class:`MeshInfo` with the triangle -> polygon map.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if not path.exists():
        raise MeshError("mesh file not found", path)
    if path.is_dir():
        raise MeshError("is a folder, expected a mesh file", path)
    if suffix not in READERS:
        raise MeshError(f"unsupported mesh format '{suffix or path.name}' (supported: {', '.join(supported_formats())})", path)
    vertices, polygons = READERS[suffix](path)
    if isinstance(polygons, np.ndarray):
        faces, source = polygons, np.arange(len(polygons), dtype=np.int64)
    else:
        faces, source = triangulate_polygons(polygons, str(path))
    check_arrays(vertices, faces, str(path))
    info = MeshInfo(str(path), suffix[1:], int(source[-1]) + 1 if len(source) else 0, source)
    return vertices, faces, info


def check_arrays(vertices: np.ndarray, faces: np.ndarray, path: str = "<mesh>") -> None:
    """Raise :class:`MeshError` for an empty mesh, NaN/inf coordinates or bad indices."""
    if len(vertices) == 0:
        raise MeshError("mesh has no vertices", path)
    if len(faces) == 0:
        raise MeshError("mesh has no faces (a point cloud or line set is not a surface)", path)
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise MeshError(f"{int(bad.sum())} vertices have NaN or infinite coordinates (first: vertex {int(np.argmax(bad))})", path)
    if faces.min() < 0 or faces.max() >= len(vertices):
        face = int(np.argmax((faces < 0).any(axis=1) | (faces >= len(vertices)).any(axis=1)))
        raise MeshError(f"face {face} refers to vertex {faces[face].tolist()} but the mesh has {len(vertices)} vertices", path)


# ---------------------------------------------------------------------------
# writing


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    from faceforge.io.stagefiles import atomic_write_bytes

    lines = ["# written by faceforge"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist()]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode("ascii"))


def _write_off(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    from faceforge.io.stagefiles import atomic_write_bytes

    lines = ["OFF", f"{len(vertices)} {len(faces)} 0"]
    lines += [f"{x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"3 {a} {b} {c}" for a, b, c in faces.tolist()]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode("ascii"))


def _write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    import meshio

    tmp = path.with_name(f".{path.name}.tmp.ply")
    meshio.write_points_cells(tmp, vertices, [("triangle", faces)], file_format="ply", binary=True)
    tmp.replace(path)


def save_mesh(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """Write a triangle mesh: OBJ, OFF and PLY (binary float64) round-trip exactly;
    STL and GLB (via trimesh) store float32.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int, indices into ``vertices``
    """
    path = Path(path)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"save_mesh: expected vertices (n, 3) and faces (m, 3), got {vertices.shape} and {faces.shape}")
    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".obj":
        _write_obj(path, vertices, faces)
    elif suffix == ".off":
        _write_off(path, vertices, faces)
    elif suffix == ".ply":
        _write_ply(path, vertices, faces)
    elif suffix in (".stl", ".glb"):
        import trimesh

        from faceforge.io.stagefiles import atomic_write_bytes

        data = trimesh.Trimesh(vertices, faces, process=False).export(file_type=suffix[1:])
        atomic_write_bytes(path, data if isinstance(data, bytes) else data.encode("utf-8"))
    else:
        raise MeshError(f"cannot write format '{suffix}' (writable: .glb, .obj, .off, .ply, .stl)", path)
    return path
