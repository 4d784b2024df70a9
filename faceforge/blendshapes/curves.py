"""ARKit weight tracks in and out (issue 27).

In: :func:`read_weights` reads

* the CSV that Unreal's Live Link Face app records: ``Timecode,BlendShapeCount,EyeBlinkLeft,...``
  (ARKit's names with a capital first letter), then one row per frame; the head and eye
  rotation columns it appends (``HeadYaw``, ... ``RightEyeRoll``) are read and ignored;
* a plain CSV ``frame`` or ``time`` (optional) then one column per shape (ARKit's names, either
  capitalisation);
* JSON: ``{"fps": 60, "frames": [{"jawOpen": 0.3, ...}, ...]}`` or a list of such objects, or
  ``{"names": [...], "weights": [[...], ...]}``.

Every weight must lie in [0, 1], every name be one of ARKit's 52, at least one shape be named,
every row have the header's length, the text be UTF-8 and quotes closed: otherwise a :class:`faceforge.exceptions.FapError` naming ``file:line``.

Out: :func:`solve_weights` finds per frame the weights in [0, 1] of baked shapes whose sum best
matches a frame's displacement (bounded least squares); :func:`write_weights` writes them as a
Live Link Face CSV (``.csv``) or JSON (``.json``).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from faceforge.blendshapes.arkit import ARKIT_NAMES

#: the columns Live Link Face appends after the 52 shapes (read, ignored)
LIVE_LINK_EXTRA = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
                   "RightEyeYaw", "RightEyePitch", "RightEyeRoll")
_BY_LOWER = {n.lower(): n for n in ARKIT_NAMES}
#: the rate of the timecode's frame field :func:`write_weights` writes (Live Link Face's 60)
TIMECODE_RATE = 60.0
#: the timecode rates a take's frame field is matched against (:func:`timecode_rate`)
TIMECODE_RATES = (24, 25, 30, 48, 50, 60, 120)
#: block Gauss-Seidel passes of :func:`solve_weights`' smoothness term
SWEEPS = 20
#: the sweeps stop early when no weight moves more than this in a pass
SWEEP_TOL = 1e-5
_TOLERANCE = 1e-6   # weights written with 6 decimals may round a hair past 1


def _error(path, line, msg):
    from faceforge.exceptions import FapError

    return FapError(msg, f"{path}:{line}" if line else path)


def _timecode(text: str):
    """``HH:MM:SS:FF(.fff)`` (Live Link Face) -> (whole seconds, frame field); None if not one."""
    parts = text.strip().split(":")
    if len(parts) != 4:
        return None
    try:
        return 3600 * int(parts[0]) + 60 * int(parts[1]) + int(parts[2]), float(parts[3])
    except ValueError:
        return None


def timecode_rate(frame_fields) -> float:
    """The timecode rate of a take: the smallest of :data:`TIMECODE_RATES` above every frame field
    (exact for takes of a second or more; Live Link Face writes 60 or 30)."""
    top = max(frame_fields, default=0.0)
    return next((float(r) for r in TIMECODE_RATES if r > top), float(TIMECODE_RATES[-1]))


def read_weights(path, default_fps: float = 60.0) -> tuple[list, np.ndarray, float]:
    """(names [k] ARKit names in the file's column order, weights (F, k) float in [0, 1], fps).

    fps: the JSON's ``fps``; for a Live Link CSV the rate its timecodes step at (the frame field's
    rate from :func:`timecode_rate`), else ``default_fps``."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise _error(path, 0, f"cannot read the weights: {exc.__class__.__name__}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:   # e.g. a UTF-16 export: name the line of the first bad byte
        line = raw[:exc.start].count(b"\n") + 1
        raise _error(path, line, f"not UTF-8 text (byte 0x{raw[exc.start]:02x})") from None
    if path.suffix.lower() == ".json":
        names, weights, fps = _read_json(path, text, default_fps)
    else:
        names, weights, fps = _read_csv(path, text, default_fps)
    if not names:
        raise _error(path, 1 if path.suffix.lower() != ".json" else 0,
                     "no blendshape column: the take names none of ARKit's 52 shapes")
    from faceforge.mpeg4.fap import FPS_RANGE

    if not (np.isfinite(fps) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise _error(path, 0, f"frame rate must be in [{FPS_RANGE[0]:g}, {FPS_RANGE[1]:g}] fps, got {fps:g}")
    return names, weights, fps


def _name(path, line, raw: str) -> str | None:
    raw = raw.strip()
    if raw in LIVE_LINK_EXTRA:
        return None
    name = _BY_LOWER.get(raw.lower())
    if name is None:
        raise _error(path, line, f"unknown blendshape name {raw!r} (ARKit's 52 names, e.g. eyeBlinkLeft)")
    return name


def _read_csv(path, text, default_fps):
    reader = csv.reader(text.splitlines(), strict=True)
    rows = []
    try:
        for row in reader:
            rows.append(row)
    except csv.Error as exc:     # a NUL byte, a quote left open
        raise _error(path, reader.line_num, f"not a CSV file: {exc}") from None
    if not rows or not rows[0]:
        raise _error(path, 1, "empty file: expected a header of blendshape names")
    header = [h.strip() for h in rows[0]]
    skip = [i for i, h in enumerate(header) if h.lower() in ("timecode", "blendshapecount", "frame", "time")]
    cols, names = [], []
    for i, h in enumerate(header):
        if i in skip:
            continue
        name = _name(path, 1, h)
        if name is not None:
            if name in names:
                raise _error(path, 1, f"blendshape {name} given twice")
            cols.append(i)
            names.append(name)
    out, stamps = [], []
    tc = header.index("Timecode") if "Timecode" in header else -1
    for k, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise _error(path, k, f"{len(row)} fields, the header has {len(header)}")
        try:
            values = [float(row[i]) for i in cols]
        except ValueError:
            raise _error(path, k, "a weight is not a number") from None
        bad = [(names[j], v) for j, v in enumerate(values) if not (-_TOLERANCE <= v <= 1 + _TOLERANCE)]
        if bad:
            raise _error(path, k, f"{bad[0][0]} = {bad[0][1]:g} is outside [0, 1]")
        out.append(values)
        if tc >= 0:
            stamps.append(_timecode(row[tc]))
    if not out:
        raise _error(path, 2, "no frames")
    fps = default_fps
    if len(stamps) > 2 and all(s is not None for s in stamps):
        rate = timecode_rate([f for _, f in stamps])
        step = np.median(np.diff([sec + f / rate for sec, f in stamps]))
        if step > 0:
            fps = float(round(1.0 / step, 3))
    return names, np.clip(np.asarray(out, dtype=float), 0.0, 1.0), fps


def _read_json(path, text, default_fps):
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _error(path, exc.lineno, f"not JSON: {exc.msg}") from None
    except RecursionError:
        raise _error(path, 0, "JSON nested too deeply") from None
    except ValueError as exc:      # e.g. an integer of more than 4,300 digits
        raise _error(path, 0, f"not JSON: {exc}") from None
    try:
        return _json_weights(path, data, default_fps)
    except (TypeError, ValueError, AttributeError) as exc:   # a name or weight of the wrong kind
        from faceforge.exceptions import FapError

        if isinstance(exc, FapError):
            raise
        raise _error(path, 0, f"expected {{\"names\": [...], \"weights\": [[...], ...], \"fps\": N}} or "
                              f"{{\"frames\": [{{name: weight, ...}}, ...]}} of numbers ({exc})") from None


def _json_weights(path, data, default_fps):
    """names, weights, fps of a parsed JSON take (:func:`_read_json`); TypeError/ValueError on a
    value of the wrong kind."""
    fps = default_fps
    if isinstance(data, dict) and "names" in data:
        if not isinstance(data["names"], list) or not all(isinstance(n, str) for n in data["names"]):
            raise _error(path, 0, "names must be a list of ARKit blendshape names")
        names = [_name(path, 0, n) for n in data["names"]]
        w = np.asarray(data.get("weights", []), dtype=float)
        fps = float(data.get("fps", fps))
        if w.ndim != 2 or w.shape[1] != len(names):
            raise _error(path, 0, f"weights must be (frames, {len(names)})")
    else:
        frames = data.get("frames") if isinstance(data, dict) else data
        if isinstance(data, dict):
            fps = float(data.get("fps", fps))
        if not isinstance(frames, list) or not frames or not all(isinstance(f, dict) for f in frames):
            raise _error(path, 0, "expected {\"frames\": [{name: weight, ...}, ...]}")
        names = []
        for f in frames:
            for n in f:
                name = _name(path, 0, n)
                if name is not None and name not in names:
                    names.append(name)
        w = np.zeros((len(frames), len(names)))
        for i, f in enumerate(frames):
            for n, v in f.items():
                name = _name(path, 0, n)
                if name is not None:
                    w[i, names.index(name)] = float(v)
    bad = np.argwhere(~((w >= -_TOLERANCE) & (w <= 1 + _TOLERANCE)))
    if len(bad):
        i, j = bad[0]
        raise _error(path, 0, f"frame {i}: {names[j]} = {w[i, j]:g} is outside [0, 1]")
    return names, np.clip(w, 0.0, 1.0), fps


def solve_weights(frames: np.ndarray, neutral: np.ndarray, shapes: np.ndarray, ridge: float = 0.0,
                  smooth: float = 0.0, sweeps: int = SWEEPS) -> np.ndarray:
    """Per frame the weights ``w`` in [0, 1] minimising ``|neutral + sum_k w_k (shape_k - neutral)
    - frame|^2 + ridge * s^2 |w|^2``, plus over the take ``smooth * s^2 sum_f |w_f - w_(f-1)|^2``
    (bounded least squares, scipy ``lsq_linear``; ``s`` the mean norm of the shapes' displacement
    fields, so ``ridge`` and ``smooth`` are unitless).

    frames : (F, n, 3) in take order; neutral : (n, 3); shapes : (k, n, 3); ridge >= 0
    (``curves.ridge``), smooth >= 0 (``curves.smooth``): with nearly collinear shapes, e.g.
    mouthRollLower / mouthShrugLower, either keeps a small change of the motion from trading one's
    weight for the other's; ``smooth`` ties each frame to its neighbours, solved by ``sweeps``
    block Gauss-Seidel passes over the frames (each a bounded solve per frame, warm from the
    frame-by-frame solution) -> (F, k) float.
    """
    from scipy.optimize import lsq_linear

    D = (np.asarray(shapes, float) - neutral).reshape(len(shapes), -1).T   # (3n, k)
    Y = (np.asarray(frames, float) - neutral).reshape(len(frames), -1)
    live = np.linalg.norm(D, axis=0) > 0
    out = np.zeros((len(Y), len(shapes)))
    if not live.any():
        return out
    A = D[:, live]
    k = A.shape[1]
    scale = np.linalg.norm(A, axis=0).mean()
    if ridge > 0:
        A = np.vstack([A, np.sqrt(ridge) * scale * np.eye(k)])
    # the normal equations' QR once, then per frame a small bounded solve: (3n [+ k], k) -> (k, k)
    q, r = np.linalg.qr(A)
    B = Y @ q[: D.shape[0]]                      # (F, k); the ridge rows' targets are 0
    w = np.array([lsq_linear(r, b, bounds=(0.0, 1.0), method="bvls").x for b in B]).reshape(len(Y), k)
    if smooth > 0 and len(Y) > 1:
        w = _smooth_sweeps(r, B, w, np.sqrt(smooth) * scale, sweeps)
    out[:, live] = w
    return np.clip(out, 0.0, 1.0)


def _smooth_sweeps(r: np.ndarray, B: np.ndarray, w: np.ndarray, s: float, sweeps: int) -> np.ndarray:
    """Minimise ``sum_f |r w_f - B_f|^2 + s^2 sum_f |w_f - w_(f-1)|^2`` over ``0 <= w <= 1`` by
    passes over the frames, each frame's bounded solve with its neighbours held (at most ``sweeps``,
    fewer once no weight moves :data:`SWEEP_TOL`; MakeHuman's joy, 108 frames x 42 shapes: 20 passes
    reach the optimum's objective to 1e-5 at smooth 0.1, 0.4 % at 1): r (k, k), B (F, k), w (F, k)
    the start -> (F, k)."""
    from scipy.optimize import lsq_linear

    k = r.shape[1]
    eye = np.eye(k)
    w = w.copy()
    for _ in range(sweeps):
        moved = 0.0
        for f in range(len(B)):
            nb = [w[g] for g in (f - 1, f + 1) if 0 <= g < len(B)]
            M = np.vstack([r] + [s * eye] * len(nb))
            rhs = np.concatenate([B[f]] + [s * x for x in nb])
            new = lsq_linear(M, rhs, bounds=(0.0, 1.0), method="bvls").x
            moved = max(moved, float(np.abs(new - w[f]).max()))
            w[f] = new
        if moved < SWEEP_TOL:
            break
    return w


def near_duplicates(neutral: np.ndarray, shapes: np.ndarray, names, cosine: float = 0.95) -> list:
    """The pairs of shapes whose displacement fields are nearly parallel or opposite: ``(name_a,
    name_b, cosine)`` with ``|cosine| >= cosine``, the most alike first. neutral (n, 3), shapes
    (k, n, 3), names [k]. A solve cannot tell such a pair apart: a small change of the motion moves
    weight from one to the other (or turns both on, cancelling, when opposite)."""
    D = (np.asarray(shapes, float) - np.asarray(neutral, float)).reshape(len(shapes), -1)
    norm = np.linalg.norm(D, axis=1)
    live = np.flatnonzero(norm > 0)
    G = (D[live] / norm[live, None]) @ (D[live] / norm[live, None]).T
    pairs = [(names[live[i]], names[live[j]], float(G[i, j])) for i in range(len(live))
             for j in range(i + 1, len(live)) if abs(G[i, j]) >= cosine]
    return sorted(pairs, key=lambda p: -abs(p[2]))


def mix_shapes(neutral: np.ndarray, shapes: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The blendshape mix ``neutral + sum_k w_k (shape_k - neutral)``: neutral (n, 3), shapes
    (k, n, 3), weights (F, k) -> (F, n, 3)."""
    neutral = np.asarray(neutral, float)
    return neutral + np.einsum("fk,knd->fnd", np.asarray(weights, float), np.asarray(shapes, float) - neutral)


def reproduction_error(frames: np.ndarray, neutral: np.ndarray, shapes: np.ndarray,
                       weights: np.ndarray) -> tuple[float, float]:
    """How well the shapes mixed by ``weights (F, k)`` reproduce ``frames (F, n, 3)``: the RMS
    error relative to the RMS motion from ``neutral`` (a fraction), and the largest vertex error
    (skin units)."""
    frames = np.asarray(frames, float)
    diff = mix_shapes(neutral, shapes, weights) - frames
    moved = frames - np.asarray(neutral, float)
    rel = float(np.sqrt(np.mean(diff ** 2)) / max(np.sqrt(np.mean(moved ** 2)), 1e-30))
    return rel, float(np.linalg.norm(diff, axis=-1).max())


def write_weights(path, names, weights: np.ndarray, fps: float) -> Path:
    """Write ``weights (F, k)`` of ``names`` as a Live Link Face CSV (``.csv``: timecode at
    ``fps``, BlendShapeCount, one column per ARKit name, all 52 in ARKit's order, absent ones 0,
    then the nine rotation columns as 0) or JSON (``.json``: ``{"fps", "names", "weights"}``)."""
    from faceforge.io.export_common import atomic_write_bytes

    path = Path(path)
    w = np.asarray(weights, dtype=float)
    if path.suffix.lower() == ".json":
        body = json.dumps({"fps": fps, "names": list(names), "weights": np.round(w, 6).tolist()})
        return atomic_write_bytes(path, body.encode("utf-8"))
    if path.suffix.lower() != ".csv":
        raise ValueError(f"{path}: curves are written as .csv or .json")
    full = np.zeros((len(w), len(ARKIT_NAMES)))
    for j, n in enumerate(names):
        full[:, ARKIT_NAMES.index(n)] = w[:, j]
    lines = [",".join(["Timecode", "BlendShapeCount", *(n[0].upper() + n[1:] for n in ARKIT_NAMES),
                       *LIVE_LINK_EXTRA])]
    for f, row in enumerate(full):
        t = f / fps
        h, rem = divmod(t, 3600)
        m, s = divmod(rem, 60)
        frame = (s - int(s)) * TIMECODE_RATE
        tc = f"{int(h):02d}:{int(m):02d}:{int(s):02d}:{frame:06.3f}"
        lines.append(",".join([tc, str(len(ARKIT_NAMES) + len(LIVE_LINK_EXTRA)),
                               *(f"{x:.6f}" for x in row), *("0" for _ in LIVE_LINK_EXTRA)]))
    return atomic_write_bytes(path, ("\n".join(lines) + "\n").encode("utf-8"))
