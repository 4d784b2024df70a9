"""Merging a user's partial landmark file with detected points, and writing the results:
the landmark file (the project's format, one comment per point), ``report.json`` and
``landmarks.png`` (front and side views, each point labelled)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from faceforge.landmarks.detect import Detection


def merge(det: Detection, given, vertices: np.ndarray) -> Detection:
    """``det`` with the FDPs of ``given`` (:class:`faceforge.io.landmarks.RawLandmarks`, the
    user's partial file, ids referring to ``vertices``) taking their place: the user's vertex
    and position are kept as written (a vertex alone gets its position)."""
    ids, pos, vert = list(det.ids), det.positions.copy(), det.vertex.copy()
    method, conf, views, spread = list(det.method), det.confidence.copy(), list(det.views), det.spread.copy()
    for j, k in enumerate(given.ids):
        v_id = int(given.vertex[j])
        p = given.position[j] if np.isfinite(given.position[j]).all() else vertices[v_id]
        what = f"given in {Path(given.path).name}"
        if k in ids:
            i = ids.index(k)
            pos[i], vert[i], method[i], conf[i], views[i], spread[i] = p, v_id, what, 1.0, [], 0.0
        else:
            ids.append(k)
            pos = np.vstack([pos, p])
            vert = np.append(vert, v_id)
            method.append(what)
            conf = np.append(conf, 1.0)
            views.append([])
            spread = np.append(spread, 0.0)
    return Detection(tuple(ids), pos, vert, method, conf, views, spread, dict(det.info))


def _order(ids) -> list:
    from faceforge.mpeg4.tables import FDP_IDS

    return sorted(range(len(ids)), key=lambda i: FDP_IDS.index(ids[i]))


def landmark_yaml(det: Detection, mesh_path: str) -> str:
    """The landmark file's text (readable by :func:`faceforge.io.landmarks.read_landmarks`)."""
    from faceforge.mpeg4.tables import FDP_BY_ID

    lines = [
        "# MPEG-4 FDP landmarks found by `faceforge landmarks` (automatic: MediaPipe Face Landmarker on",
        "# headless renders, lifted onto the mesh; see report.json next to this file for each point's views",
        "# and spread). Edit any point and feed the file back with --landmarks: your points are used as written.",
        f"source_mesh: {Path(mesh_path).name}",
        f"count: {len(det.ids)}",
        "landmarks:",
    ]
    for i in _order(det.ids):
        k = det.ids[i]
        v = "null" if det.vertex[i] < 0 else str(int(det.vertex[i]))
        p = ", ".join(f"{x:.6g}" for x in det.positions[i])
        desc = FDP_BY_ID[k].description if k in FDP_BY_ID else ""
        lines.append(f'  "{k}": {{vertex: {v}, position: [{p}]}}  # {desc} | {det.method[i]}; '
                     f"confidence {det.confidence[i]:.2f}")
    return "\n".join(lines) + "\n"


def report(det: Detection, mesh_path: str, given_path: str | None) -> dict:
    """``report.json``: per point its method, confidence, views and spread; the search."""
    info = {k: v for k, v in det.info.items() if k != "plane"}
    points = {det.ids[i]: {"method": det.method[i], "confidence": round(float(det.confidence[i]), 4),
                           "views": det.views[i], "spread": round(float(det.spread[i]), 6),
                           "vertex": int(det.vertex[i]), "position": det.positions[i].tolist()}
              for i in _order(det.ids)}
    return {"mesh": str(mesh_path), "given": given_path, "count": len(det.ids), **info, "points": points}


def save_png(path, det: Detection, vertices: np.ndarray, faces: np.ndarray, title: str) -> None:
    """Front and side renders of the mesh with every point drawn and labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from faceforge.geometry.triangles import vertex_normals
    from faceforge.landmarks.raster import View, render

    frame = det.info["frame"]
    left, up, fwd = (np.asarray(frame[k]) for k in ("left", "up", "forward"))
    v = np.asarray(vertices, dtype=np.float64)
    normals = vertex_normals(v, faces)
    mid = np.mean(det.positions, axis=0)
    span = float(np.ptp((det.positions - mid) @ np.array([left, up]).T, axis=0).max())
    size = 900
    fig, axes = plt.subplots(1, 2, figsize=(16, 8.4), dpi=100)
    for ax, (name, direction) in zip(axes, (("front", -fwd), ("side (subject's left)", -left))):
        view = View(direction, up, mid, 0.62 * size / span, size)
        r = render(v, faces, normals, view)
        ax.imshow(r.image, cmap="gray", vmin=0, vmax=255)
        px = view.project(det.positions)
        given = np.array([m.startswith("given") for m in det.method])
        ax.scatter(px[~given, 0], px[~given, 1], s=14, c="crimson", zorder=3)
        ax.scatter(px[given, 0], px[given, 1], s=18, c="deepskyblue", zorder=3)
        for i, k in enumerate(det.ids):
            ax.annotate(k, px[i, :2], xytext=(3, -3), textcoords="offset points", fontsize=6.5,
                        color="yellow" if not given[i] else "deepskyblue")
        ax.set_title(name)
        ax.set_axis_off()
    fig.suptitle(title + "  (red: detected, blue: given)")
    fig.tight_layout()
    from faceforge.io.stagefiles import atomic_write_bytes
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
