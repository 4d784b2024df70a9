"""Print the table of the bad-input cases and their messages (markdown), from a real run:
``python -m tests.reliability.table [WORKDIR]`` (a fitted and bound MediaPipe workdir is
built in a temporary folder unless WORKDIR is one). docs/reliability.md holds its output."""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from .conftest import MEDIAPIPE, cli_run, snapshot
from .test_bad_inputs import CASES, run_case


def main(argv: list[str]) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="reliab-table-"))
    try:
        if argv:
            work = Path(argv[0])
        else:
            work = tmp / "work"
            for stage in (["fit", MEDIAPIPE / "face_model_with_iris.obj"], ["bind"]):
                r = cli_run("-w", work, "--set", "solver.iterations=10", *stage)
                assert r.exit_code == 0, r.stderr
        print("| case | exit | workdir unchanged | message (paths shortened) |")
        print("|---|---|---|---|")
        for i, name in enumerate(CASES):
            case = tmp / f"case{i}"
            case.mkdir()
            before = snapshot(work)
            result, _ = run_case(name, case, work)
            line = (result.stderr.strip().splitlines() or [""])[-1]
            line = line.replace(str(case), "<tmp>").replace(str(work), "<workdir>")
            line = line.replace(str(MEDIAPIPE), "samples/mediapipe")
            line = line if len(line) < 240 else line[:237] + "..."
            print(f"| {name} | {result.exit_code} | {'yes' if snapshot(work) == before else 'NO'} | "
                  f"`{line.replace('|', '/')}` |")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main(sys.argv[1:])
