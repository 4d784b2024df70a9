"""The batch through a real Dask LocalCluster (two worker processes) via --scheduler."""

from __future__ import annotations

import json
import os
import re

import pytest

from faceforge.pipeline import batch

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=40) as c:
        yield c


def test_batch_on_a_local_cluster(invoke, fake_stages, cluster, tmp_path, heads_dir, short_fap):
    out = tmp_path / "out"
    heads = [heads_dir / f"{n}.obj" for n in ("anna", "broken", "ben")]
    result = invoke("--no-progress", "batch", *heads, "--fap", short_fap, "--plugin", fake_stages,
                    "--out", out, "--scheduler", cluster.scheduler_address, "-o", ".mdd")
    assert result.exit_code == 1 and isinstance(result.exception, (SystemExit, type(None))), \
        (result.stderr, result.exception)
    report = json.loads((out / batch.REPORT_NAME).read_text())
    assert report["executor"] == f"dask {cluster.scheduler_address}"
    status = {r["name"]: r["status"] for r in report["results"]}
    assert status == {"anna": "ok", "broken": "failed", "ben": "ok"}
    broken = report["results"][1]
    assert broken["error"].startswith(str(heads_dir / "broken.obj")) and "\n" not in broken["error"]
    # the heads ran in the cluster's worker processes, not here
    pids = set()
    for name in ("anna", "ben"):
        log = (out / name / batch.HEAD_LOG).read_text()
        pids |= {int(p) for p in re.findall(r"pid (\d+)", log)}
        assert (out / name / f"{name}.mdd").exists()
    assert os.getpid() not in pids


def test_unreachable_scheduler_is_a_one_line_error(invoke, fake_stages, tmp_path, heads_dir, short_fap):
    from faceforge.exceptions import StageError

    with pytest.raises(StageError, match="cannot reach the Dask scheduler"):
        batch.run_dask([batch.make_job(heads_dir / "anna.obj", tmp_path, batch.SharedOptions(fap=str(short_fap)))],
                       "tcp://127.0.0.1:9", timeout="1s")
