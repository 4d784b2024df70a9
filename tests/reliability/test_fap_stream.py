"""A FAP track read a block at a time (issue 28): the blocks are the whole track's frames bit for
bit (holds and lip pairs carried across blocks), the checking pass keeps parse_fap's errors and
their order, memory does not grow with the take, and the stage file's spooled tables are the
bytes np.savez writes."""

from __future__ import annotations

import io
import tracemalloc
import warnings

import numpy as np
import pytest

from faceforge.exceptions import FapError
from faceforge.io.frame_stream import FrameNpzWriter
from faceforge.mpeg4 import FapTrack, format_fap, parse_fap, read_fap, write_fap
from faceforge.mpeg4.fap_stream import FapFile, content_lines


def tricky_track(n=50, seed=3) -> FapTrack:
    """Sparse masks (holds across any block boundary), one-sided lip pairs, visemes, expressions."""
    rng = np.random.default_rng(seed)
    mask = rng.random((n, 68)) < 0.15
    mask[0, 2] = True
    values = np.round(rng.normal(scale=200, size=(n, 68)))
    viseme = np.column_stack([rng.integers(0, 15, n), rng.integers(0, 15, n), rng.integers(0, 64, n), np.zeros(n)])
    expression = np.column_stack([rng.integers(0, 7, n), rng.integers(0, 64, n), rng.integers(0, 7, n),
                                  rng.integers(0, 64, n), np.zeros(n), np.zeros(n)])
    return FapTrack.from_given(25.0, mask, values, viseme, expression, name="tricky")


def _same(a: FapTrack, b: FapTrack) -> bool:
    return (a.fps == b.fps and a.name == b.name and np.array_equal(a.mask, b.mask)
            and np.array_equal(a.values, b.values, equal_nan=True) and np.array_equal(a.viseme, b.viseme)
            and np.array_equal(a.expression, b.expression) and np.array_equal(a.frame_numbers, b.frame_numbers))


@pytest.mark.parametrize("block", [1, 3, 7, 64])
def test_the_blocks_are_the_whole_track(tmp_path, block):
    track = tricky_track()
    path = write_fap(tmp_path / "t.fap", track)
    blocks = list(FapFile(path, block=block).blocks())
    assert [len(b.values) for b in blocks][:-1] == [block] * (len(blocks) - 1)
    whole = FapTrack(fps=track.fps, values=np.concatenate([b.values for b in blocks]),
                     mask=np.concatenate([b.mask for b in blocks]),
                     viseme=np.concatenate([b.viseme for b in blocks]),
                     expression=np.concatenate([b.expression for b in blocks]),
                     frame_numbers=np.concatenate([b.frame_numbers for b in blocks]), name=track.name)
    assert _same(whole, track) and _same(read_fap(path), track)


def test_lines_split_across_pieces_are_the_whole_texts_lines():
    text = "\ufeff2.1 a 25 1\r\n# c\r\n\r\n1 0\rx\u2028y\x0bz\n last "
    whole = [(i, ln.strip()) for i, ln in enumerate(text.lstrip("\ufeff").splitlines(), 1)
             if ln.strip() and not ln.strip().startswith("#")]
    for size in (1, 2, 3, 5, 100):
        pieces = [text[i:i + size] for i in range(0, len(text), size)]
        assert list(content_lines(pieces)) == whole, size


def test_a_truncated_file_is_said_before_its_first_bad_frame(tmp_path):
    mask = " ".join(["0"] * 2 + ["1"] + ["0"] * 65)
    text = f"2.1 t 25 3\n{mask}\n0 1\n{mask}\nx 2\n{mask}\n"      # a bad frame number, then truncated
    with pytest.raises(FapError, match="truncated"):
        parse_fap(text)
    with pytest.raises(FapError, match=r":5: frame number"):
        parse_fap(text + "2 3\n")


def test_a_latin1_file_reads_as_before(tmp_path):
    path = tmp_path / "l.fap"
    path.write_bytes(format_fap(tricky_track(5)).replace("tricky", "tr\xe9s").encode("latin-1"))
    assert read_fap(path).name == "tr\xe9s"


def test_reading_a_long_take_does_not_hold_it(tmp_path, monkeypatch):
    """Checking and reading 3,000 frames in blocks of 256 (64 KiB read at a time) peaks under
    2 MB of Python memory (the whole-file reader held ~4 KB a frame: ~12 MB here)."""
    from faceforge.mpeg4 import fap_stream

    monkeypatch.setattr(fap_stream, "_READ", 1 << 16)
    n = 3000
    track = tricky_track(n)
    path = write_fap(tmp_path / "long.fap", track)
    del track
    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fap = FapFile(path, block=256)
            total = sum(len(b.values) for b in fap.blocks())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert total == n
    assert peak < 4e6, f"{peak / 1e6:.1f} MB"


def test_spooled_tables_are_the_bytes_np_savez_writes(tmp_path):
    rng = np.random.default_rng(0)
    frames = rng.normal(size=(70, 5, 3)).astype(np.float32)
    c, jaw = rng.random((70, 4)), rng.random((70, 3))
    with FrameNpzWriter(tmp_path / "a.npz", 70, 5) as writer:
        for s in range(0, 70, 16):
            writer.write(frames[s:s + 16])
            writer.spool("contractions", c[s:s + 16])
            writer.spool("jaw", jaw[s:s + 16])
        writer.close(fps=np.float64(25), contractions=writer.SPOOLED, controls=np.array(["a", "b"]),
                     jaw=writer.SPOOLED)
    buf = io.BytesIO()
    np.savez(buf, frames=frames, fps=np.float64(25), contractions=c, controls=np.array(["a", "b"]), jaw=jaw)
    assert (tmp_path / "a.npz").read_bytes() == buf.getvalue()


def test_block_controls_and_summary_are_the_whole_tracks(tmp_path):
    """ControlBlocks (any block size) give track_controls' contractions, jaw, FAPs and head
    angles bit for bit, and its summary the stage's figures (unmapped FAPs, visemes, maxima)."""
    from types import SimpleNamespace

    from faceforge.animation.control_stream import ControlBlocks
    from faceforge.animation.controls import track_controls, visemes_played
    from faceforge.animation.fap_mapping import JawLevers, load_fap_mapping
    from faceforge.animation.head_motion import head_angles
    from pathlib import Path

    import faceforge

    mapping = load_fap_mapping(Path(faceforge.__file__).parent / "templates" / "fap_mapping.yaml")
    fapu = SimpleNamespace(as_dict=lambda: {n: 0.01 for n in ("IRISD", "ES", "ENS", "MNS", "MW", "AU")})
    head = SimpleNamespace(controls=list(mapping.muscles), fapu=fapu, levers=JawLevers(pitch=9.0, yaw=8.0))
    track = tricky_track(90)
    path = write_fap(tmp_path / "t.fap", track)
    c, jaw, unmapped, faps = track_controls(track, mapping, head)
    visemes, viseme_frames = visemes_played(track)
    for block in (7, 64):
        source = ControlBlocks(FapFile(path, block=block), mapping, head, turn=True)
        blocks = list(source)
        assert np.array_equal(np.concatenate([b.c for b in blocks]), c)
        assert np.array_equal(np.concatenate([b.jaw for b in blocks]), jaw)
        assert np.array_equal(np.concatenate([b.angles for b in blocks]), head_angles(faps))
        s = source.summary()
        assert (s.unmapped, s.visemes, s.viseme_frames) == (unmapped, visemes, viseme_frames)
        assert s.max_contraction == float(c.max()) and np.array_equal(s.max_jaw, jaw.max(axis=0))
        assert np.array_equal(s.max_angles, np.abs(head_angles(faps)).max(axis=0))


def test_offline_playback_in_blocks_is_the_whole_tracks():
    """animate plays a long take a block at a time; offline (play_converged), a block starts from
    the previous block's last controls and the rig as it left it: the same frames as at once."""
    from faceforge.animation.statics import SettleSettings, play_converged
    from tests.animation.test_statics import relaxing_rig

    c = np.linspace(0.0, 1.0, 12)[:, None] ** 2
    jaw = np.zeros((12, 3))
    settings = SettleSettings(tolerance=1e-6, max_frames=5)     # unconverged: the carried state shows
    whole, parts = {}, {}
    play_converged(relaxing_rig(), c, jaw, 25.0, lambda s, f: whole.update({s: f.copy()}), settings, chunk=4)
    rig, previous = relaxing_rig(), None
    for start in (0, 8):
        block = slice(start, start + 8)
        play_converged(rig, c[block], jaw[block], 25.0, lambda s, f, o=start: parts.update({o + s: f.copy()}),
                       settings, chunk=4, previous=previous)
        previous = (c[block][-1], jaw[block][-1])
    assert sorted(whole) == sorted(parts)
    assert all(np.array_equal(whole[k], parts[k]) for k in whole)
