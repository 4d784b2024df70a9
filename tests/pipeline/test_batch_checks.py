"""A batch head whose result fails its checks fails alone, is named in the summary, exports
nothing, and the batch exits 3 (1 when some head failed otherwise); ``--keep-going`` accepts it."""

from __future__ import annotations

import json

from faceforge.pipeline import batch

from .conftest import GOOD


def test_a_head_failing_its_checks_fails_alone_and_keep_going_accepts_it(invoke, fake_stages, tmp_path,
                                                                         heads_dir, short_fap, monkeypatch):
    monkeypatch.setenv("FACEFORGE_FAKE_FAIL_CHECKS", "ben")
    heads = [heads_dir / f"{n}.obj" for n in GOOD]
    out = tmp_path / "out"

    def run(*extra, names=heads):
        return invoke("--no-progress", "batch", *names, "--fap", short_fap, "--plugin", fake_stages,
                      "--out", out, "--jobs", 1, "-o", ".pc2", *extra)

    r = run()
    assert r.exit_code == 3, r.output + r.stderr
    report = json.loads((out / batch.REPORT_NAME).read_text())
    status = {h["name"]: (h["status"], h["failed_checks"]) for h in report["results"]}
    assert status == {"anna": ("ok", False), "ben": ("failed", True), "carl": ("ok", False)}
    assert "ben: " in r.output and "animate failed its checks: skin_inside_skull (2 skin vertices inside the " \
                                   "skull at frame 3)" in r.output
    assert (out / "anna" / "anna.pc2").exists() and not (out / "ben" / "ben.pc2").exists()
    assert (out / "ben" / "animate" / "stage.json").exists()          # the result is kept, cached
    again = run()                                                      # a rerun is not "ok" over it
    assert again.exit_code == 3 and not (out / "ben" / "ben.pc2").exists()
    kept = run("--keep-going")
    assert kept.exit_code == 0, kept.output + kept.stderr
    assert (out / "ben" / "ben.pc2").exists()
    assert "check failed, kept (--keep-going)" in (out / "ben" / batch.HEAD_LOG).read_text()
    # a head failing with an error beside one failing its checks: exit 1
    mixed = run(names=heads + [heads_dir / "broken.obj"])
    assert mixed.exit_code == 1
