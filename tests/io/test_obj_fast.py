"""The bulk OBJ reader (:func:`faceforge.io.mesh._read_obj_fast`) reads what the careful
line-by-line reader reads, and hands everything else to it."""

from __future__ import annotations

import numpy as np

from faceforge.io import mesh as M


def test_the_bulk_reader_agrees_with_the_careful_one_and_declines_the_rest(tmp_path, monkeypatch):
    text = "# a quad split in two\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0.5\nvn 0 0 1\nf 1/1/1 2/2/1 3//1\nf 1 3 4\n"
    v, f = M._read_obj_fast(text)
    assert np.array_equal(f, [[0, 1, 2], [0, 2, 3]]) and np.array_equal(v[3], [0, 1, 0.5])
    path = tmp_path / "q.obj"
    path.write_text(text)
    fast = M.load_mesh(path)
    monkeypatch.setattr(M, "_read_obj_fast", lambda text: None)
    slow = M.load_mesh(path)
    assert np.array_equal(fast[0], slow[0]) and np.array_equal(fast[1], slow[1])
    for other in ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",     # a quad
                  "v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\n",               # relative indices
                  "v 0 0 0 1\nv 1 0 0 1\nv 1 1 0 1\nf 1 2 3\n",            # w coordinates
                  "v 0 0 0\nv 1 0 x\nv 1 1 0\nf 1 2 3\n",                  # a bad number
                  "  v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n"):               # an indented line
        assert M._read_obj_fast(other) is None
