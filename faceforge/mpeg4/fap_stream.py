"""MPEG-4 FAP files read a block of frames at a time: a take's memory independent of its length.

:func:`faceforge.mpeg4.read_fap` used to hold the whole text, its lines and the filled
``(F, 68)`` tables at once (~4 KB a frame at the peak, issue 28). :class:`FapFile` reads the file
twice, never whole: :meth:`FapFile.__init__` checks every line (the errors, warnings and
repairs of :mod:`faceforge.mpeg4.fap`'s format, in the order the whole-text reader had) and counts the frames;
:meth:`FapFile.blocks` then yields :class:`~faceforge.mpeg4.fap.FapTrack` blocks of
:data:`BLOCK` frames whose values are those of the whole track (the hold rule carries across
blocks). Both passes keep a constant amount of memory: the bytes are read 1 MiB at a time and
decoded incrementally.

:func:`parse_fap` and :func:`read_fap` (exported by :mod:`faceforge.mpeg4`) are built on the
same passes, so there is one reader.
"""

from __future__ import annotations

import codecs
import warnings
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from faceforge.exceptions import FapError

from .fap import (_N_VALUES, FapTrack, FapWarning, _hold_rows, _integer, _number, _parse_header, _parse_mask,
                  complete_values)
from .fap_range import clamp_block, range_summary
from .tables import N_EXPRESSION_VALUES, N_FAPS, N_VISEME_VALUES

#: frames per block (a multiple of the playback's chunk of 64 frames); ~4 MB of tables a block
BLOCK = 1024
#: bytes read at a time
_READ = 1 << 20


def content_lines(pieces: Iterable[str]) -> Iterator[tuple[int, str]]:
    """``(1-based line number, stripped line)`` of every line that is neither blank nor a
    comment, from text given in pieces of any size: the lines of ``str.splitlines`` of the
    whole text (a ``\\r\\n`` split between two pieces is one line end), leading BOMs dropped."""
    carry, number, start = "", 0, True
    for piece in pieces:
        if start:
            piece = piece.lstrip("\ufeff")
            start = not piece
        lines = (carry + piece).splitlines(keepends=True)
        carry = lines.pop() if lines else ""
        for line in lines:
            number += 1
            stripped = line.strip()
            if stripped and not stripped.startswith("#"):
                yield number, stripped
    if carry:
        stripped = carry.strip()
        if stripped and not stripped.startswith("#"):
            yield number + 1, stripped


def _file_pieces(path: Path, encoding: str) -> Iterator[str]:
    """The text of ``path`` decoded with ``encoding``, :data:`_READ` bytes at a time."""
    decoder = codecs.getincrementaldecoder(encoding)()
    try:
        with open(path, "rb") as fh:
            while True:
                data = fh.read(_READ)
                yield decoder.decode(data, final=not data)
                if not data:
                    return
    except OSError as exc:
        raise FapError(f"cannot read FAP file: {exc.strerror or exc}", path) from None


def _frame(mask_at, data_at, source: str, previous: int | None):
    """Parse one frame's mask and data lines (``(line number, text)`` each; ``previous``: the
    frame number before, which this one must exceed). Returns ``(bits
    (68,) bool given and finite, given (68,), viseme (4,), expression (6,), frame number,
    finite)`` (``finite``: no value of the line was inf or nan)."""
    (mask_line, mask_text), (data_line, data_text) = mask_at, data_at
    bits = _parse_mask(mask_text.split(), source, mask_line)
    data_tokens = data_text.split()
    expected = int(_N_VALUES[bits].sum())
    if len(data_tokens) != expected + 1:
        raise FapError(f"data line must have the frame number and {expected} values for the mask on line "
                       f"{mask_line}, got {len(data_tokens) - 1} values", source, data_line)
    number = _integer(data_tokens[0], source, data_line, "frame number")
    if previous is not None and number <= previous:
        raise FapError(f"frame number {number} does not increase (previous {previous})", source, data_line)
    numbers = np.array([_number(t, source, data_line, "FAP value") for t in data_tokens[1:]])
    ids = np.flatnonzero(bits)
    chunks = np.split(numbers, np.cumsum(_N_VALUES[ids])[:-1]) if ids.size else []
    given, viseme, expression = np.zeros(N_FAPS), np.zeros(N_VISEME_VALUES), np.zeros(N_EXPRESSION_VALUES)
    kept = np.zeros(N_FAPS, dtype=bool)
    finite = True
    for index, chunk in zip(ids, chunks):
        if not np.all(np.isfinite(chunk)):
            finite = False
            continue  # treated as absent in this frame
        kept[index] = True
        if index == 0:
            viseme[:] = chunk
        elif index == 1:
            expression[:] = chunk
        else:
            given[index] = chunk[0]
    return kept, given, viseme, expression, number, finite


class _Raw:
    """One block of parsed frames before the fill rules: ``mask, given (k, 68)``, ``viseme
    (k, 4)``, ``expression (k, 6)``, ``frame_numbers (k,)``, and the data lines with a
    non-finite value."""

    def __init__(self, size: int):
        self.mask = np.zeros((size, N_FAPS), dtype=bool)
        self.given = np.zeros((size, N_FAPS))
        self.viseme = np.zeros((size, N_VISEME_VALUES))
        self.expression = np.zeros((size, N_EXPRESSION_VALUES))
        self.frame_numbers = np.zeros(size, dtype=np.int64)
        self.repaired: list[int] = []
        self.n = 0

    def add(self, parsed, data_line: int) -> None:
        kept, given, viseme, expression, number, finite = parsed
        k = self.n
        self.mask[k], self.given[k], self.viseme[k], self.expression[k] = kept, given, viseme, expression
        self.frame_numbers[k] = number
        if not finite:
            self.repaired.append(data_line)
        self.n += 1


def _raw_blocks(lines: Iterator[tuple[int, str]], source: str, strict: bool, block: int,
                previous: int | None = None) -> Iterator[_Raw]:
    """Parse the body (after the header) into :class:`_Raw` blocks of ``block`` frames (the
    last one shorter). Raises the first frame's :class:`FapError` in file order; a mask line
    without its data line is left to the caller (it is not yielded: the caller counts lines)."""
    raw = _Raw(block)
    for mask_at in lines:
        data_at = next(lines, None)
        if data_at is None:
            raise _Truncated(mask_at[0])
        parsed = _frame(mask_at, data_at, source, previous)
        previous = parsed[4]
        if strict and not parsed[5]:
            raise FapError("non-finite FAP value (inf or nan)", source, data_at[0])
        raw.add(parsed, data_at[0])
        if raw.n == block:
            yield raw
            raw = _Raw(block)
    if raw.n:
        yield raw


_TRUNCATED = "file ends after a mask line without its data line (truncated?)"


class _Truncated(Exception):
    """The body ended after a mask line (its line number in ``args[0]``)."""


class FapFile:
    """A FAP file checked whole and read a block at a time (module docstring).

    ``FapFile(path, strict=False, block=BLOCK)`` reads the file once to check it (raising
    :class:`FapError` naming the file and line, warning :class:`FapWarning` for the repairs, as
    :func:`parse_fap` does); then ``fps``, ``name``, ``version`` and
    ``n_frames`` (the frames present) describe it and :meth:`blocks` reads it again.
    ``source`` (``path`` when None) names it in messages; ``pieces``: a callable returning the
    text in pieces (for :func:`parse_fap`'s strings; default: the file's bytes, UTF-8 or else
    Latin-1).
    """

    def __init__(self, path: str | Path, *, strict: bool = False, block: int = BLOCK,
                 pieces: Callable[[], Iterable[str]] | None = None, source: str | None = None):
        self.path = Path(path)
        self.source = str(self.path if source is None else source)
        self.strict = bool(strict)
        self.block = max(1, int(block))
        if pieces is None:
            self.encoding = "utf-8"
            try:
                for _ in _file_pieces(self.path, "utf-8"):
                    pass
            except UnicodeDecodeError:
                self.encoding = "latin-1"
            pieces = lambda: _file_pieces(self.path, self.encoding)   # noqa: E731
        self._pieces = pieces
        self._check()

    def _lines(self) -> Iterator[tuple[int, str]]:
        return content_lines(self._pieces())

    def _header(self, lines) -> int:
        first = next(lines, None)
        if first is None:
            raise FapError("empty FAP file (no header line)", self.source)
        self.version, self.name, self.fps, self.n_header = _parse_header(first[1].split(), self.source, first[0])
        return first[0]

    def _check(self) -> None:
        """The checking pass: the errors of ``parse_fap`` in its order (a truncated body, then
        no frames, then the first bad frame), then its warnings."""
        lines = self._lines()
        header_line = self._header(lines)
        n, repaired = 0, []
        worst, count = np.zeros(N_FAPS), np.zeros(N_FAPS, dtype=np.int64)
        try:
            for raw in _raw_blocks(lines, self.source, self.strict, self.block):
                n += raw.n
                repaired.extend(raw.repaired[:max(0, 21 - len(repaired))])
                _, w, c = clamp_block(raw.given[:raw.n], raw.mask[:raw.n])
                worst, count = np.maximum(worst, w), count + c
        except _Truncated as exc:
            raise FapError(_TRUNCATED, self.source, exc.args[0]) from None
        except FapError:
            body, last = 0, 0      # a truncated file is said before its first bad frame
            rest = self._lines()
            next(rest)
            for last, _ in rest:
                body += 1
            if body % 2:
                raise FapError(_TRUNCATED, self.source, last) from None
            raise
        if n == 0:
            raise FapError("no frames after the header", self.source, header_line)
        self.n_frames = n
        self._warn(repaired, range_summary(worst, count), header_line)

    def _warn(self, repaired: list[int], clamped: str, header_line: int) -> None:
        if repaired:
            shown = ", ".join(str(x) for x in repaired[:20]) + (" ..." if len(repaired) > 20 else "")
            warnings.warn(f"{self.source}: non-finite FAP values on lines {shown}: treated as absent from those "
                          "frames (held from the previous frame or copied from the lip partner)", FapWarning,
                          stacklevel=3)
        if clamped:
            if self.strict:
                raise FapError(f"FAP values past the standard's range: {clamped}", self.source)
            warnings.warn(f"{self.source}: FAP values past the standard's range, clamped: {clamped}", FapWarning,
                          stacklevel=3)
        if self.n_frames != self.n_header:
            message = f"header says {self.n_header} frames but the file has {self.n_frames}"
            if self.strict:
                raise FapError(message, self.source, header_line)
            warnings.warn(f"{self.source}:{header_line}: {message}; using the {self.n_frames} frames present",
                          FapWarning, stacklevel=3)

    def blocks(self) -> Iterator[FapTrack]:
        """The frames as :class:`FapTrack` blocks of ``block`` frames (the last one shorter),
        each with the values of the whole track in those frames: clamped, lip pairs and holds
        applied, holds carried from the block before."""
        lines = self._lines()
        self._header(lines)
        state = np.zeros(N_FAPS), np.zeros(N_VISEME_VALUES), np.zeros(N_EXPRESSION_VALUES)
        for raw in _raw_blocks(lines, self.source, False, self.block):
            track = _filled(raw, state, self)
            state = (np.nan_to_num(track.values[-1]), track.viseme[-1], track.expression[-1])
            yield track

    def read(self) -> FapTrack:
        """The whole track (what :func:`read_fap` returns)."""
        parts = list(self.blocks())
        return FapTrack(fps=self.fps, values=np.concatenate([p.values for p in parts]),
                        mask=np.concatenate([p.mask for p in parts]),
                        viseme=np.concatenate([p.viseme for p in parts]),
                        expression=np.concatenate([p.expression for p in parts]),
                        frame_numbers=np.concatenate([p.frame_numbers for p in parts]),
                        name=self.name, version=self.version)


def _filled(raw: _Raw, state, meta: FapFile) -> FapTrack:
    """The block ``raw`` with the fill rules of :meth:`FapTrack.from_given`, the hold starting
    from ``state`` (the last filled values (68,) with columns 0, 1 zero, viseme (4,),
    expression (6,) rows of the block before; zeros for the first): a first row giving every
    FAP the state's value is put in front and dropped after the fill."""
    k = raw.n
    mask, given = raw.mask[:k], clamp_block(raw.given[:k], raw.mask[:k])[0]
    given = np.where(mask, given, 0.0)
    given[:, :2] = 0.0
    every = np.ones((1, N_FAPS), dtype=bool)
    values = complete_values(np.vstack([every, mask]), np.vstack([state[0][None], given]))[1:]
    viseme = _hold_rows(np.vstack([state[1][None], raw.viseme[:k]]), np.concatenate([[True], mask[:, 0]]))[1:]
    expression = _hold_rows(np.vstack([state[2][None], raw.expression[:k]]),
                            np.concatenate([[True], mask[:, 1]]))[1:]
    return FapTrack(fps=meta.fps, values=values, mask=mask.copy(), viseme=viseme, expression=expression,
                    frame_numbers=raw.frame_numbers[:k].copy(), name=meta.name, version=meta.version)


def parse_fap(text: str, source: str | Path = "<string>", *, strict: bool = False) -> FapTrack:
    """Parse the text of a FAP file (see :mod:`faceforge.mpeg4.fap` for the format and the
    repairs).

    Parameters
    ----------
    text : str
    source : str or Path
        Named in errors and warnings.
    strict : bool
        Turn every repair into a :class:`FapError`.

    Returns
    -------
    FapTrack

    Raises
    ------
    FapError
        Naming ``source`` and the line.
    """
    return FapFile(str(source), strict=strict, pieces=lambda: (text,), source=str(source)).read()


def read_fap(path: str | Path, *, strict: bool = False) -> FapTrack:
    """Read a FAP file (:func:`parse_fap`; errors name ``path`` and the line). The text is
    never held whole; :meth:`FapFile.blocks` reads a long take a block at a time."""
    return FapFile(path, strict=strict).read()
