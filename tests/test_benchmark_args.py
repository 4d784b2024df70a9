"""The benchmarks' workdir arguments: ``--help`` or a mistyped path is never taken for a workdir
(a benchmark used to measure nothing and write an empty results file)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from _util import workdir_args  # noqa: E402

DOC = """A benchmark.

More text."""


def test_workdirs_and_flags(tmp_path):
    (tmp_path / "a").mkdir()
    args = workdir_args(DOC, [str(tmp_path / "a"), "--signed"], {"--signed": "both signs"})
    assert args.workdirs == [tmp_path / "a"] and args.signed


@pytest.mark.parametrize("argv, code", [(["--help"], 0), ([], 2), (["/no/such/workdir"], 2), (["--bogus"], 2)])
def test_help_or_a_bad_path_is_not_a_workdir(tmp_path, capsys, argv, code):
    with pytest.raises(SystemExit) as exc:
        workdir_args(DOC, argv)
    assert exc.value.code == code
    if argv == ["--help"]:
        assert "A benchmark." in capsys.readouterr().out
