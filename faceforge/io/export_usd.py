"""USD: the animated head as one Mesh prim with time-sampled points.

``x.usda`` is written as text by faceforge itself (no dependency); ``x.usdc`` / ``x.usd``
(binary crate) need Pixar's ``usd-core`` (``pip install usd-core``) and fail on use, with
that hint, without it. Both hold the same scene::

    #usda 1.0
    (defaultPrim = "faceforge", startTimeCode = 0, endTimeCode = F - 1,
     timeCodesPerSecond = fps, framesPerSecond = fps, upAxis = "Y", metersPerUnit = 1)
    def Xform "faceforge" (kind = "component")
        def Mesh "head"
            int[] faceVertexCounts, int[] faceVertexIndices     # the user's polygons
            point3f[] points = frame 0; points.timeSamples = {k: frame k}
            float3[] extent.timeSamples                         # per-frame bounding box

Time code ``k`` is faceforge frame ``k`` (time ``k / fps``), vertex ``i`` the user's vertex
``i``; polygons keep their corner order (USD's default ``rightHanded`` orientation is OBJ's
counter-clockwise). ``metersPerUnit = 1``: one unit of your mesh is one scene unit, as when
its OBJ is imported (USD's default, 0.01, would make an importer shrink a head modelled in
any unit 100-fold). Points are float32, written with 9 significant digits, so a USD reader
gets faceforge's float32 frames back exactly. ``up_axis``: "Y" or "Z" (USD knows no other);
``faceforge animate`` passes the up axis of the user's own frame (``fit.orientation``).
Blender (File > Import > USD), Maya, Houdini and usdview read either file; Blender turns the
time samples into a Mesh Sequence Cache modifier.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .export_common import (
    ExportError,
    atomic_write_bytes,
    faces_to_csr,
    register_exporter,
    validate_animation,
)

#: the prims faceforge writes
ROOT_PRIM, MESH_PRIM = "faceforge", "head"


def _points(frame: np.ndarray) -> str:
    """``[(x, y, z), ...]`` with 9 significant digits (exact for float32)."""
    flat = frame.astype(np.float32).astype(np.float64).ravel()
    return "[" + ", ".join(["(%.9g, %.9g, %.9g)"] * len(frame)) % tuple(flat) + "]"


def _ints(values) -> str:
    return "[" + ", ".join(map(str, np.asarray(values, dtype=np.int64).tolist())) + "]"


def _fps(fps: float) -> str:
    return repr(float(fps)) if float(fps) != int(fps) else str(int(fps))


def _check_up_axis(up_axis: str, path) -> str:
    if up_axis not in ("Y", "Z"):
        raise ExportError(f"USD up axis must be 'Y' or 'Z', got {up_axis!r}", path)
    return up_axis


def write_usda(path: str | Path, frames, faces, fps: float, *, up_axis: str = "Y") -> Path:
    """Write a text USD file (see the module docstring).

    frames : (n_frames, n_verts, 3) float; faces : (m, k) int array or sequence of
    polygons, 0-based (required: a USD mesh needs its faces); fps : float > 0.
    """
    data = validate_animation(frames, fps).astype(np.float32)
    if faces is None:
        raise ExportError("a USD mesh needs its faces", path)
    indices, starts = faces_to_csr(faces, data.shape[1])
    up_axis = _check_up_axis(up_axis, path)
    lo, hi = data.min(axis=1), data.max(axis=1)
    n = len(data)
    head = (f'#usda 1.0\n(\n    defaultPrim = "{ROOT_PRIM}"\n    startTimeCode = 0\n'
            f"    endTimeCode = {n - 1}\n    timeCodesPerSecond = {_fps(fps)}\n"
            f'    framesPerSecond = {_fps(fps)}\n    upAxis = "{up_axis}"\n    metersPerUnit = 1\n'
            f'    doc = "faceforge animation: {n} frames, {data.shape[1]} vertices"\n)\n\n'
            f'def Xform "{ROOT_PRIM}" (\n    kind = "component"\n)\n{{\n'
            f'    def Mesh "{MESH_PRIM}"\n    {{\n'
            '        uniform token orientation = "rightHanded"\n'
            '        uniform token subdivisionScheme = "none"\n'
            f"        int[] faceVertexCounts = {_ints(np.diff(starts))}\n"
            f"        int[] faceVertexIndices = {_ints(indices)}\n"
            f"        point3f[] points = {_points(data[0])}\n"
            "        point3f[] points.timeSamples = {\n")
    chunks = [head.encode()]
    for k in range(n):
        chunks.append(f"            {k}: {_points(data[k])},\n".encode())
    chunks.append(b"        }\n        float3[] extent.timeSamples = {\n")
    for k in range(n):
        chunks.append(f"            {k}: {_points(np.stack([lo[k], hi[k]]))},\n".encode())
    chunks.append(b"        }\n    }\n}\n")
    return atomic_write_bytes(path, chunks)


def _pxr():
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt  # noqa: F401
    except ImportError:
        return None
    import pxr

    return pxr


def require_usd_core(path) -> None:
    """Raise ExportError naming ``path`` when ``usd-core`` is not installed."""
    if _pxr() is None:
        raise ExportError("writing binary USD needs usd-core (pip install usd-core); "
                          "or write text USD with a .usda suffix", path)


def write_usdc(path: str | Path, frames, faces, fps: float, *, up_axis: str = "Y") -> Path:
    """Write a binary USD (crate) file through ``usd-core``: the scene of :func:`write_usda`."""
    require_usd_core(path)
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    data = validate_animation(frames, fps).astype(np.float32)
    if faces is None:
        raise ExportError("a USD mesh needs its faces", path)
    indices, starts = faces_to_csr(faces, data.shape[1])
    up_axis = _check_up_axis(up_axis, path)
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        layer = Sdf.Layer.CreateNew(str(tmp), args={"format": "usdc"})
        stage = Usd.Stage.Open(layer)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(len(data) - 1)
        stage.SetTimeCodesPerSecond(float(fps))
        stage.SetFramesPerSecond(float(fps))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        root = UsdGeom.Xform.Define(stage, f"/{ROOT_PRIM}")
        Usd.ModelAPI(root.GetPrim()).SetKind("component")
        stage.SetDefaultPrim(root.GetPrim())
        mesh = UsdGeom.Mesh.Define(stage, f"/{ROOT_PRIM}/{MESH_PRIM}")
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.diff(starts).astype(np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(indices.astype(np.int32)))
        points, extent = mesh.CreatePointsAttr(), mesh.CreateExtentAttr()
        points.Set(Vt.Vec3fArray.FromNumpy(data[0]))
        for k, frame in enumerate(data):
            points.Set(Vt.Vec3fArray.FromNumpy(frame), Usd.TimeCode(k))
            lo, hi = frame.min(axis=0).tolist(), frame.max(axis=0).tolist()
            extent.Set(Vt.Vec3fArray([Gf.Vec3f(*lo), Gf.Vec3f(*hi)]), Usd.TimeCode(k))
        layer.Save()
        del stage, layer
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)     # atomic: a reader never sees half a file
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def up_axis_of(rotation) -> str:
    """USD ``upAxis`` of the user's frame from ``fit.npz``'s ``user_rotation (3, 3)`` (its
    row 1 is the user's up): "Z" for a +Z-up head (nearest axis: a head straightened by
    ``fit.straighten_deg`` has an up a few degrees off it), else "Y" (USD has no other axes)."""
    up = np.asarray(rotation, dtype=float)[1]
    return "Z" if int(np.argmax(np.abs(up))) == 2 and up[2] > 0 else "Y"


def read_usd(path: str | Path) -> tuple[np.ndarray, float, list[int], list[int], str]:
    """Read a USD file written by faceforge through ``usd-core`` (an independent reader).

    Returns ``(frames (F, n, 3) float32, fps, faceVertexCounts, faceVertexIndices, upAxis)``.
    """
    if _pxr() is None:
        raise ExportError("reading USD needs usd-core (pip install usd-core)", path)
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise ExportError("not a USD file", path)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/{ROOT_PRIM}/{MESH_PRIM}"))
    if not mesh:
        raise ExportError(f"no mesh /{ROOT_PRIM}/{MESH_PRIM}", path)
    start, end = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    attr = mesh.GetPointsAttr()
    frames = np.stack([np.asarray(attr.Get(Usd.TimeCode(k)), dtype=np.float32) for k in range(start, end + 1)])
    return (frames, float(stage.GetTimeCodesPerSecond()), list(mesh.GetFaceVertexCountsAttr().Get()),
            list(mesh.GetFaceVertexIndicesAttr().Get()), str(UsdGeom.GetStageUpAxis(stage)))


register_exporter(".usda", write_usda)
register_exporter(".usdc", write_usdc)
register_exporter(".usd", write_usdc)
