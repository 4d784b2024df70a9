"""MPEG-4 FAP files (text format, versions 2.0 and 2.1): reader, writer, :class:`FapTrack`.

File layout (blank lines and lines starting with ``#`` are ignored anywhere; tokens are
separated by spaces or tabs; LF, CRLF or CR line ends)::

    2.1 track_name 25 108          <- version, name (may be empty or contain spaces), fps, nframes
    0 0 1 1 1 ... (68 x 0/1)       <- mask: which FAPs this frame gives
    0 12 -3 ...                    <- frame number, then one value per set bit in FAP order;
    ...                               FAP 1 (viseme) takes 4 values, FAP 2 (expression) 6

Semantics (applied identically by :func:`read_fap` and :meth:`FapTrack.from_given`):

1. a FAP given in a frame takes the given value;
2. the inner-lip FAPs 4..13 and outer-lip FAPs 51..60 describe the same motion
   (:data:`~faceforge.mpeg4.tables.LIP_PAIRS`): when a frame gives one of a pair and not the
   other, the other takes the same value;
3. any other FAP holds its value from the previous frame (0 = neutral before the first
   value). Viseme and expression parameters hold the same way.

Repairs (``strict=False``, the default; with ``strict=True`` each is a :class:`FapError`):

* a non-finite value (``inf``, ``-inf``, ``nan``) is treated as if the FAP were absent from
  that frame (rule 2 or 3 fills it); one :class:`FapWarning` lists the lines;
* a frame count that disagrees with the header: the frames present are used, with a warning;
* a value past the range a face can take (:mod:`faceforge.mpeg4.fap_range`, e.g. a head
  turned more than 90 degrees, a jaw opened by three mouth-nose separations) is clamped to
  it, with one warning naming the FAPs and the largest value of each.

Everything else that is malformed -- a wrong header, a mask that is not 68 zeros/ones, a data
line with too few or too many values (e.g. a truncated file), a non-numeric token, frame
numbers that are not increasing integers (or larger than :data:`MAX_FRAME_NUMBER`), an fps
outside :data:`FPS_RANGE`, no frames -- raises :class:`FapError` naming the
file and line.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from faceforge.exceptions import FapError

from .tables import LIP_PAIRS, N_EXPRESSION_VALUES, N_FAPS, N_VISEME_VALUES

#: versions of the text format this module reads and writes
SUPPORTED_VERSIONS = ("2.0", "2.1")
_N_VALUES = np.ones(N_FAPS, dtype=np.int64)
_N_VALUES[0] = N_VISEME_VALUES
_N_VALUES[1] = N_EXPRESSION_VALUES


class FapWarning(UserWarning):
    """A FAP file was repaired while reading (see the module docstring)."""


@dataclass(eq=False)
class FapTrack:
    """A FAP animation: per-frame values of the 68 MPEG-4 FAPs.

    Attributes
    ----------
    fps : float
        Frames per second (> 0).
    values : (n_frames, 68) float64
        Column ``k`` is FAP ``k + 1`` in its FAPU, after the fill rules (hold, lip pairs).
        Columns 0 and 1 (the high-level FAPs viseme and expression) are NaN: their
        parameters live in ``viseme`` and ``expression``.
    mask : (n_frames, 68) bool
        What the file (or the caller) gave in each frame, before any filling. Columns 0/1
        say whether the frame gave the viseme / expression parameters.
    viseme : (n_frames, 4) float64
        viseme_select1, viseme_select2, viseme_blend, viseme_def (held like the others).
    expression : (n_frames, 6) float64
        expression_select1, expression_intensity1, expression_select2,
        expression_intensity2, init_face, expression_def.
    frame_numbers : (n_frames,) int64
        The frame numbers of the data lines, strictly increasing (usually 0, 1, 2, ...).
    name : str
        Header name (single-spaced, may be empty).
    version : str
        ``"2.0"`` or ``"2.1"``.
    """

    fps: float
    values: np.ndarray
    mask: np.ndarray
    viseme: np.ndarray
    expression: np.ndarray
    frame_numbers: np.ndarray
    name: str = "faceforge"
    version: str = "2.1"

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=np.float64)
        self.mask = np.asarray(self.mask, dtype=bool)
        self.viseme = np.asarray(self.viseme, dtype=np.float64)
        self.expression = np.asarray(self.expression, dtype=np.float64)
        self.frame_numbers = np.asarray(self.frame_numbers, dtype=np.int64)
        n = self.values.shape[0] if self.values.ndim == 2 else -1
        shapes = {
            "values": (self.values.shape, (n, N_FAPS)),
            "mask": (self.mask.shape, (n, N_FAPS)),
            "viseme": (self.viseme.shape, (n, N_VISEME_VALUES)),
            "expression": (self.expression.shape, (n, N_EXPRESSION_VALUES)),
            "frame_numbers": (self.frame_numbers.shape, (n,)),
        }
        for key, (got, want) in shapes.items():
            if n < 0 or got != want:
                raise ValueError(f"FapTrack.{key}: expected shape {want}, got {got}")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"FapTrack.fps must be finite and > 0, got {self.fps!r}")
        if self.version not in SUPPORTED_VERSIONS:
            raise ValueError(f"FapTrack.version must be one of {SUPPORTED_VERSIONS}, got {self.version!r}")
        if n and np.any(np.diff(self.frame_numbers) <= 0):
            raise ValueError("FapTrack.frame_numbers must be strictly increasing")

    @property
    def n_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def times(self) -> np.ndarray:
        """``(n_frames,) float64`` seconds since the first frame: ``(frame - first) / fps``."""
        if self.n_frames == 0:
            return np.zeros(0)
        return (self.frame_numbers - self.frame_numbers[0]) / self.fps

    def fap(self, fap_id: int) -> np.ndarray:
        """``(n_frames,) float64``: the values of low-level FAP ``fap_id`` (3..68)."""
        if not 3 <= fap_id <= N_FAPS:
            raise ValueError(f"low-level FAP ids are 3..{N_FAPS}, got {fap_id}")
        return self.values[:, fap_id - 1]

    @classmethod
    def from_given(
        cls,
        fps: float,
        mask: np.ndarray,
        values: np.ndarray,
        viseme: np.ndarray | None = None,
        expression: np.ndarray | None = None,
        *,
        frame_numbers: np.ndarray | None = None,
        name: str = "faceforge",
        version: str = "2.1",
    ) -> "FapTrack":
        """Build a track from given values, applying the file semantics (hold, lip pairs).

        Parameters
        ----------
        fps : float
        mask : (n, 68) bool
            Which entries are given; entries of ``values`` (and rows of ``viseme`` /
            ``expression``) outside the mask are ignored.
        values : (n, 68) float
            Given low-level values in FAPU (columns 0, 1 ignored); must be finite where given.
        viseme : (n, 4) float, optional
            Used in frames where ``mask[:, 0]``.
        expression : (n, 6) float, optional
            Used in frames where ``mask[:, 1]``.
        frame_numbers : (n,) int, optional
            Default ``0 .. n-1``.
        """
        mask = np.asarray(mask, dtype=bool)
        values = np.asarray(values, dtype=np.float64)
        if mask.ndim != 2 or mask.shape[1] != N_FAPS or values.shape != mask.shape:
            raise ValueError(f"mask and values must both be (n, {N_FAPS}); got {mask.shape} and {values.shape}")
        n = mask.shape[0]
        viseme = np.zeros((n, N_VISEME_VALUES)) if viseme is None else np.asarray(viseme, dtype=np.float64)
        expression = (
            np.zeros((n, N_EXPRESSION_VALUES)) if expression is None else np.asarray(expression, dtype=np.float64)
        )
        if viseme.shape != (n, N_VISEME_VALUES) or expression.shape != (n, N_EXPRESSION_VALUES):
            raise ValueError(f"viseme must be ({n}, 4) and expression ({n}, 6); got {viseme.shape}, {expression.shape}")
        given = np.where(mask, values, 0.0)
        given[:, :2] = 0.0
        if not np.all(np.isfinite(given)):
            raise ValueError("given FAP values must be finite")
        if not (np.all(np.isfinite(viseme[mask[:, 0]])) and np.all(np.isfinite(expression[mask[:, 1]]))):
            raise ValueError("given viseme / expression values must be finite")
        filled = complete_values(mask, given)
        return cls(
            fps=float(fps),
            values=filled,
            mask=mask.copy(),
            viseme=_hold_rows(viseme, mask[:, 0]),
            expression=_hold_rows(expression, mask[:, 1]),
            frame_numbers=np.arange(n) if frame_numbers is None else frame_numbers,
            name=name,
            version=version,
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, FapTrack):
            return NotImplemented
        return (
            self.fps == other.fps
            and self.name == other.name
            and self.version == other.version
            and np.array_equal(self.mask, other.mask)
            and np.array_equal(self.values, other.values, equal_nan=True)
            and np.array_equal(self.viseme, other.viseme)
            and np.array_equal(self.expression, other.expression)
            and np.array_equal(self.frame_numbers, other.frame_numbers)
        )

    __hash__ = None  # mutable arrays


def _forward_fill(raw: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Hold the last known entry of each column; 0 before the first one.

    raw, known : (n, k) float, (n, k) bool -> (n, k) float64
    """
    n = raw.shape[0]
    rows = np.where(known, np.arange(n)[:, None], -1)
    rows = np.maximum.accumulate(rows, axis=0) if n else rows
    cols = np.broadcast_to(np.arange(raw.shape[1]), raw.shape)
    return np.where(rows >= 0, raw[np.maximum(rows, 0), cols], 0.0)


def _hold_rows(rows: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Hold whole rows (viseme / expression parameter vectors) where ``known`` is False."""
    return _forward_fill(rows, np.repeat(known[:, None], rows.shape[1], axis=1))


def complete_values(mask: np.ndarray, given: np.ndarray) -> np.ndarray:
    """Apply the lip-pair and hold rules to given low-level FAP values.

    Parameters
    ----------
    mask : (n, 68) bool
        Given entries.
    given : (n, 68) float
        Values in FAPU where ``mask``; anything elsewhere.

    Returns
    -------
    (n, 68) float64
        Filled values; columns 0 and 1 are NaN.
    """
    raw = np.array(given, dtype=np.float64)
    known = np.array(mask, dtype=bool)
    inner, outer = LIP_PAIRS[:, 0] - 1, LIP_PAIRS[:, 1] - 1
    only_inner = mask[:, inner] & ~mask[:, outer]
    only_outer = mask[:, outer] & ~mask[:, inner]
    raw[:, outer] = np.where(only_inner, raw[:, inner], raw[:, outer])
    raw[:, inner] = np.where(only_outer, raw[:, outer], raw[:, inner])
    known[:, outer] |= only_inner
    known[:, inner] |= only_outer
    filled = _forward_fill(raw, known)
    filled[:, :2] = np.nan
    return filled


# ---------------------------------------------------------------- reading


def _number(token: str, source: str, line: int, what: str) -> float:
    """Parse one numeric token (``inf``/``nan`` allowed, returned as such)."""
    try:
        if "_" in token:
            raise ValueError(token)
        return float(token)
    except ValueError:
        raise FapError(f"{what}: {token!r} is not a number", source, line) from None


#: largest frame number (and frame count) accepted: differences of such numbers stay exact
#: in int64 and float64 (2**53), and no take reaches it (a year at 1,000 fps is 3e10 frames)
MAX_FRAME_NUMBER = 2 ** 53
#: frame rates accepted, frames per second
FPS_RANGE = (0.1, 1000.0)


def _integer(token: str, source: str, line: int, what: str) -> int:
    if len(token) > 30:
        raise FapError(f"{what}: {token[:20]}... is not an integer of at most 16 digits", source, line)
    try:
        value = int(token)
    except ValueError:
        number = _number(token, source, line, what)
        if not (math.isfinite(number) and number == int(number)):
            raise FapError(f"{what}: {token!r} is not an integer", source, line) from None
        value = int(number)
    if abs(value) > MAX_FRAME_NUMBER:
        raise FapError(f"{what}: {token!r} is out of range (at most {MAX_FRAME_NUMBER:,} in size)", source, line)
    return value


def _parse_header(tokens: list[str], source: str, line: int) -> tuple[str, str, float, int]:
    if len(tokens) < 3:
        raise FapError(f"header must be 'version name fps nframes', got {' '.join(tokens)!r}", source, line)
    version = tokens[0]
    if version not in SUPPORTED_VERSIONS:
        raise FapError(f"unsupported FAP file version {version!r} (supported: 2.0, 2.1)", source, line)
    fps = _number(tokens[-2], source, line, "header fps")
    if not (math.isfinite(fps) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise FapError(f"header fps must be a number in [{FPS_RANGE[0]:g}, {FPS_RANGE[1]:g}], got {tokens[-2]!r}",
                       source, line)
    n_frames = _integer(tokens[-1], source, line, "header frame count")
    if n_frames < 0:
        raise FapError(f"header frame count must be >= 0, got {n_frames}", source, line)
    return version, " ".join(tokens[1:-2]), fps, n_frames


def _parse_mask(tokens: list[str], source: str, line: int) -> np.ndarray:
    if len(tokens) != N_FAPS:
        raise FapError(f"mask line must have {N_FAPS} entries (0 or 1), got {len(tokens)}", source, line)
    bad = [t for t in tokens if t not in ("0", "1")]
    if bad:
        raise FapError(f"mask entries must be 0 or 1, got {bad[0]!r}", source, line)
    return np.array([t == "1" for t in tokens], dtype=bool)


# parse_fap and read_fap live in fap_stream (one reader, which also reads a long file a block
# of frames at a time); faceforge.mpeg4 exports them.


# ---------------------------------------------------------------- writing


def _format_number(value: float) -> str:
    """Shortest text that parses back to exactly ``value`` (integers without a point)."""
    value = float(value)
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def format_fap(track: FapTrack, newline: str = "\n") -> str:
    """The FAP file text of ``track``: only the given (masked) values are written.

    ``parse_fap(format_fap(t)) == t`` for every track built by :func:`parse_fap` or
    :meth:`FapTrack.from_given`.
    """
    if track.name != " ".join(track.name.split()):
        raise ValueError(f"FAP track name {track.name!r} must be single-spaced text without line breaks")
    if track.n_frames == 0:
        raise ValueError("cannot write a FAP track with no frames")
    header = [track.version, track.name, _format_number(track.fps), str(track.n_frames)]
    out = [" ".join(item for item in header if item)]
    for frame in range(track.n_frames):
        bits = track.mask[frame]
        out.append(" ".join("1" if b else "0" for b in bits))
        items = [str(int(track.frame_numbers[frame]))]
        for index in np.flatnonzero(bits):
            if index == 0:
                items.extend(_format_number(v) for v in track.viseme[frame])
            elif index == 1:
                items.extend(_format_number(v) for v in track.expression[frame])
            else:
                items.append(_format_number(track.values[frame, index]))
        out.append(" ".join(items))
    return newline.join(out) + newline


def write_fap(path: str | Path, track: FapTrack, *, newline: str = "\n") -> Path:
    """Write ``track`` as a FAP file (UTF-8) through a temporary file renamed into place.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    text = format_fap(track, newline=newline)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as handle:
            handle.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path
