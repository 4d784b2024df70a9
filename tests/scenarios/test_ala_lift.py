"""The levator labii alaeque nasi lifts its ala (``bind.ala_mm``, faceforge.skin.ala; docs/notes/nose21.md).

On the MakeHuman sample, fitted and bound with the ala's rule on: levator_labii_inner_L at 0.5
lifts the left ala (the skin between FDPs 9.5 and 9.1) 2.5 mm (0.8 with the rule off: its skin
on the bone by its rays and ``bind.nose_on_bone``), the right crease (9.2) 0.4 mm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

MESH = Path(__file__).resolve().parents[2] / "samples" / "makehuman" / "mh_head_default.obj"


@pytest.fixture(scope="module")
def head(tmp_path_factory):
    from click.testing import CliRunner

    from faceforge.animation.rig import BoundHead
    from faceforge.cli import cli
    from faceforge.io.config import load_config

    wd = tmp_path_factory.mktemp("ala")
    for args in (["fit", str(MESH)], ["bind"]):
        result = CliRunner().invoke(cli, ["-q", "-w", str(wd), "--set", "bind.ala_mm=5", *args],
                                    catch_exceptions=False)
        assert result.exit_code == 0, result.output
    return BoundHead(wd / "fit", wd / "bind", load_config(sets=["bind.ala_mm=5"]))


def test_the_levator_alaeque_nasi_lifts_its_own_ala(head):
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.animation.playback import static_poses

    h = head
    mm = units_per_mm(h.landmarks)
    ala = int(np.argmin(np.linalg.norm(h.rest - 0.5 * (h.landmarks["9.1"] + h.landmarks["9.5"]), axis=1)))
    ctr = np.zeros((1, len(h.controls)))
    ctr[0, list(h.controls).index("levator_labii_inner_L")] = 0.5
    d = (static_poses(h.rig, ctr, np.zeros((1, 3)), 25.0, settle=40)[0] - h.rest) / mm
    assert d[ala, 1] > 1.6, d[ala]                              # up (0.8 mm without the rule)
    assert np.linalg.norm(d[h.fdp_vertex["9.2"]]) < 1.0, d[h.fdp_vertex["9.2"]]   # the other side
