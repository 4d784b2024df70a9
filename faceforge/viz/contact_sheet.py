"""A contact sheet: chosen frames of an animation side by side in one PNG (matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def pick_frames(n_frames: int, count: int = 6, spec: str | None = None) -> list[int]:
    """Frame indices to show.

    ``spec`` is a comma-separated list of frame numbers (``"0,10,25"``; negative counts from
    the end); without it ``count`` frames evenly spaced from first to last. Out-of-range
    numbers raise ValueError naming them.
    """
    if n_frames < 1:
        raise ValueError("the animation has no frames")
    if spec:
        try:
            idx = [int(tok) for tok in spec.split(",") if tok.strip()]
        except ValueError:
            raise ValueError(f"frame list must be integers separated by commas, got {spec!r}") from None
        bad = [i for i in idx if not -n_frames <= i < n_frames]
        if bad:
            raise ValueError(f"frames {bad} are outside 0..{n_frames - 1}")
        return [i % n_frames for i in idx]
    count = max(1, min(count, n_frames))
    return sorted(set(np.linspace(0, n_frames - 1, count).round().astype(int).tolist()))


def face_region(vertices: np.ndarray, landmarks: dict) -> np.ndarray | None:
    """(n,) bool: the vertices of ``vertices (n, 3)`` (head frame, +Y up) in the face's box:
    from a little below the chin (FDP 2.1) to above the brows (4.x, else the outer eye corners
    3.7 / 3.12), within three half eye distances of the eyes' middle; None without those FDPs."""
    if not all(k in landmarks for k in ("2.1", "3.7", "3.12")):
        return None
    lm = {k: np.asarray(p, dtype=float) for k, p in landmarks.items()}
    v = np.asarray(vertices, dtype=float)
    top = max(lm[k][1] for k in ("4.1", "4.2", "4.3", "4.4", "3.7", "3.12") if k in lm)
    half = 0.5 * abs(lm["3.7"][0] - lm["3.12"][0])
    cx = 0.5 * (lm["3.7"][0] + lm["3.12"][0])
    keep = (v[:, 1] >= lm["2.1"][1] - 0.15 * half) & (v[:, 1] <= top + 0.6 * half) & \
        (np.abs(v[:, 0] - cx) <= 1.5 * half)
    return keep if keep.any() else None


def contact_sheet(out_png, frames: np.ndarray, faces: np.ndarray, indices, fps: float,
                  view: str = "front", cols: int | None = None, title: str | None = None,
                  panel: float = 2.6, dpi: int = 110, focus: bool = False,
                  labels=None, region: np.ndarray | None = None, smooth: bool = True,
                  heat: float | None = None, heat_label: str | None = None,
                  dim: np.ndarray | None = None) -> Path:
    """Write a grid of shaded renders of ``frames[indices]``.

    Parameters
    ----------
    out_png : path of the PNG to write
    frames : (F, n, 3) float, vertex positions per frame (project frame: +Y up, face +Z)
    faces : (m, 3) int
    indices : frame indices to draw (each panel is titled with its frame and time)
    fps : frames per second (for the time stamps)
    view : "front" | "side" | "top" (see :mod:`faceforge.viz.render`)
    cols : panels per row (default: up to 6)

    All panels share one scale (the union of the drawn frames' extents), so motion between
    panels is visible as motion. ``focus`` zooms on the vertices that move (>= 35 % of the
    largest displacement between the first drawn frame and the others), padded by 30 %;
    ``region`` ((n,) bool) frames those vertices instead (e.g. the head without its neck).
    ``labels``: one title per panel instead of its frame and time. ``smooth``: smooth shading
    with vertex normals through a z-buffer (:mod:`faceforge.viz.smooth`); else one flat colour a
    triangle, painted back to front. ``heat``
    (units of the frames, e.g. 5 mm): each panel after the first gets a displacement heat map
    of that scale beside it (distance from the first drawn frame; ``heat_label`` names the
    scale in its title, e.g. "0-8 mm"). ``dim`` ((n,) in [0, 1]): vertices drawn darker in the
    smooth panels (the mouth's cavity, :func:`faceforge.viz.smooth.mouth_cavity`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from faceforge.viz.render import Layer, draw_layers, view_matrix

    from faceforge.viz.smooth import draw_heat, draw_smooth

    indices = list(indices)
    frames = np.asarray(frames, dtype=float)
    cols = cols or min(len(indices), 6)
    if heat is not None:
        cols *= 2   # each pose with its heat map beside it
    per = 2 if heat is not None else 1
    rows = -(-len(indices) * per // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(panel * cols, panel * 1.15 * rows), dpi=dpi,
                             squeeze=False)
    r = view_matrix(view)
    shown = frames[indices]
    keep = np.ones(shown.shape[1], dtype=bool) if region is None else np.asarray(region, dtype=bool)
    if focus:
        # frame the part that moves: vertices displaced by >= 35 % of the largest displacement
        disp = np.linalg.norm(shown - shown[:1], axis=2).max(axis=0)
        if disp.max() > 0:
            keep = disp >= 0.35 * disp.max()
    proj = shown[:, keep].reshape(-1, 3) @ r.T
    lo, hi = proj[:, :2].min(axis=0), proj[:, :2].max(axis=0)
    pad = (0.3 if focus else 0.04) * (hi - lo).max()
    for ax in axes.ravel():
        ax.axis("off")
    names = list(labels) if labels is not None else [f"frame {i}  ({i / fps:.2f} s)" for i in indices]
    flat = axes.ravel()
    box, px = (lo - pad, hi + pad), int(round(2 * panel * dpi))   # a panel's view, rasterised at twice its pixels
    for k, (i, name) in enumerate(zip(indices, names)):
        pair = flat[per * k:per * k + per]
        if smooth:
            draw_smooth(pair[0], frames[i], faces, view, dim=dim, box=box, px=px)
        else:
            draw_layers(pair[0], [Layer(frames[i], faces)], view, labels=False)
        pair[0].set_title(name, fontsize=8)
        if heat is not None:
            draw_heat(pair[1], frames[i], frames[indices[0]], faces, heat, view, box=box, px=px)
            pair[1].set_title(f"{name}: moved ({heat_label or f'0-{heat:.3g}'})", fontsize=7)
        for ax in pair:
            ax.set_xlim(box[0][0], box[1][0])
            ax.set_ylim(box[0][1], box[1][1])
            ax.set_aspect("equal")
    top = 1.0
    if title:
        fig.suptitle(title, fontsize=10)
        top = 1.0 - 0.35 / fig.get_figheight()   # a band of 0.35 in above the panels' labels
    fig.tight_layout(rect=(0.0, 0.0, 1.0, top))
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png)
    plt.close(fig)
    return out_png
