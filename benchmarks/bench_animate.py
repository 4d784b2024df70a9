"""Benchmark of the animation loop (issue 7). Run: ``python benchmarks/bench_animate.py [--quick]``.

Measures the per-frame time of skull + muscles + skin, broken down by layer, at the paper's
10 Gauss-Seidel iterations, while playing ``samples/fap/joy.fap``:

* ``synthetic`` (always): a Mesh_D-sized head (UV-sphere skin of 4,874 vertices / 9,744
  triangles vs the paper's Mesh_D 4,904 / 9,541) with a closed cranium and mandible, one
  active zygomaticus and 25 passive sheets (26 muscles, like the paper's map), bound by the
  real bind stage and simulated by the real layered system (``tests/animation/synthetic.py``);
* ``--workdir DIR`` (optional): a real head already fitted and bound in DIR;
* ``--sweep`` (optional, slow): every ``samples/fap/*.fap``, and a generated track of the
  fourteen visemes (``visemes_all_fourteen.fap``, :func:`faceforge.mpeg4.viseme_track`), on
  the three sample heads through the CLI (fit, bind, animate -o .pc2): checks (NaN, inverted
  triangles, skin inside the skull), ms/frame and the .pc2 round trip, per head and file;
* ``--calibrated DIR`` (optional, repeatable): the summary and per-FAP rows of a
  ``faceforge calibrate`` run in DIR.

Writes ``benchmarks/results/animate.json``. The paper (Table I, one core of a 2.4 GHz Core2)
reports 50 ms per frame for Mesh_D; the target here is <= 3 ms. Wall-clock per layer (best of 7 repeats: the shared VM has
phases in which a two-thread step takes 1.5x as long) and the process's
CPU time per frame are both recorded: on a busy shared machine the CPU time is the honest one.
Not a test.
"""

from __future__ import annotations

import argparse
import functools
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from _util import SAMPLE_HEADS, print_table, write_results  # noqa: E402

TARGET_MS = 3.0
PAPER_MESH_D_MS = 50.0


def synthetic_head(tmp: Path, count, extra: int, sets=()):
    """Fit + bind the synthetic head in ``tmp``; return (BoundHead, mapping). ``sets``:
    config overrides (``"solver.partitions=1"``) for the simulation."""
    import yaml

    import faceforge.animation.rig as rig
    from faceforge.animation.fap_mapping import mapping_from_dict
    from faceforge.io.config import load_config
    from faceforge.pipeline import StageContext
    from faceforge.pipeline.stages.bind import run as run_bind
    from tests.animation import synthetic as S

    S.write_fit(tmp / "fit", count=count, extra_muscles=extra)
    (tmp / "bind").mkdir()
    run_bind(StageContext(name="bind", config=load_config(), params={}, out_dir=tmp / "bind",
                          workdir=tmp, deps=("fit",)))
    real = rig.muscle_system
    rig.muscle_system = functools.partial(S.muscle_system, extra=extra)
    try:
        head = rig.BoundHead(tmp / "fit", tmp / "bind", load_config(sets=sets))
    finally:
        rig.muscle_system = real
    (tmp / "mapping.yaml").write_text(yaml.safe_dump(S.MAPPING))
    return head, mapping_from_dict(S.MAPPING)


def real_head(workdir: Path, sets=()):
    import faceforge.pipeline.mapping as stage
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config

    config = load_config(remembered=workdir / "config.yaml", sets=sets)
    head = BoundHead(workdir / "fit", workdir / "bind", config)
    cal = stage.calibrated_mapping_path(workdir)
    return head, load_fap_mapping(cal if cal.exists() else stage.mapping_template_path(config))


def measure(head, mapping, frames: int, repeats: int, rival=None) -> dict:
    """Best-of-``repeats`` per-layer ms per frame over ``frames`` frames of joy.fap.

    ``rival``: the same head built with other settings (one partition); its repeats alternate
    with ``head``'s, and its figures and the ratio go under ``"one_partition"``."""
    from faceforge.animation.controls import track_controls
    from faceforge.animation.playback import Timings, play
    from faceforge.mpeg4 import read_fap

    track = read_fap(ROOT / "samples" / "fap" / "joy.fap")
    c, jaw, _, _ = track_controls(track, mapping, head)
    c, jaw = c[:frames], jaw[:frames]
    heads = [head] + ([rival] if rival is not None else [])
    for h in heads:
        h.rig.reset()
        play(h.rig, c[:3], jaw[:3], track.fps)                 # compile / warm caches
    best = [None] * len(heads)
    cpu = [[] for _ in heads]
    frames_out = [None] * len(heads)
    for _ in range(repeats):
        for i, h in enumerate(heads):                           # side by side, alternating
            h.rig.reset()
            t = Timings()
            c0 = time.process_time()
            frames_out[i] = play(h.rig, c, jaw, track.fps, timings=t)
            cpu[i].append(1e3 * (time.process_time() - c0) / len(jaw))
            ms = t.per_frame_ms()
            if best[i] is None or ms["total"] < best[i]["total"]:
                best[i] = ms
    extra = {}
    if rival is not None:
        extra["one_partition"] = {
            "ms_per_frame": {k: round(v, 3) for k, v in best[1].items()},
            "cpu_ms_per_frame_best": round(min(cpu[1]), 3),
            "ratio_total": round(best[0]["total"] / best[1]["total"], 3),
            "max_frame_difference": float(np.abs(np.asarray(frames_out[0])
                                                 - np.asarray(frames_out[1])).max()),
        }
    best, cpu = best[0], cpu[0]
    skin_c = head.skin.model.constraint_count
    return {
        "skin_vertices": int(len(head.rest)), "skin_triangles": int(len(head.faces)),
        "muscles": len(head.system.muscles), "muscle_particles": int(head.system.particle_count()),
        "constraints_skin": int(skin_c), "constraints_muscles": int(head.system.constraint_count()),
        "frames": int(len(jaw)), "fps": float(track.fps),
        "iterations": int(head.system.settings.iterations),
        "ms_per_frame": {k: round(v, 3) for k, v in best.items()},
        # CPU time of this process per frame (a busy shared machine inflates the wall clock)
        "cpu_ms_per_frame_best": round(min(cpu), 3),
        "partitions": int(head.system.settings.partitions), **extra,
    }




def threads_info() -> dict:
    """numba's threading layer and thread count, as the partitioned steps use them."""
    import numba

    from faceforge.pbd.threads import threaded

    on = threaded()
    return {"threaded": on, "layer": numba.threading_layer() if on else None,
            "numba_threads": int(numba.get_num_threads())}


def sweep(root: Path, heads, faps) -> dict:
    """Every FAP file on every sample head through the CLI (fit, bind, animate -o .pc2);
    per (head, file): frames, checks, ms/frame, and whether the .pc2 reads back equal."""
    import json

    from click.testing import CliRunner

    from faceforge.cli import cli
    from faceforge.io.export import read_pc2
    from faceforge.io.stagefiles import load_npz

    runner = CliRunner()
    out = {}
    for head in heads:
        wd = root / head
        t0 = time.perf_counter()
        for args in (["fit", str(SAMPLE_HEADS[head])], ["bind"]):
            r = runner.invoke(cli, ["-q", "-w", str(wd), *args])
            if r.exit_code != 0:
                out[head] = {"error": r.output.strip()[-300:]}
                break
        else:
            out[head] = {"fit_bind_s": round(time.perf_counter() - t0, 1), "files": {}}
            for fap in faps:
                pc2 = wd / f"{fap.stem}.pc2"
                r = runner.invoke(cli, ["-q", "-w", str(wd), "animate", "--fap", str(fap), "-o", str(pc2)])
                if r.exit_code != 0:
                    out[head]["files"][fap.name] = {"error": (r.output.strip() or repr(r.exception))[-300:]}
                    continue
                rep = json.loads((wd / "animate" / "report.json").read_text())
                frames = load_npz(wd / "animate" / "animation.npz")["frames"]
                out[head]["files"][fap.name] = {
                    "frames": rep["frames"], "checks": rep["checks"],
                    "ms_per_frame": round(rep["per_frame_ms"]["total"], 2),
                    "pc2_round_trip": bool(np.array_equal(read_pc2(pc2)[0], frames))}
            print(head, json.dumps({k: (v["checks"]["ok"] if "checks" in v else v)
                                    for k, v in out[head]["files"].items()}))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    ap.add_argument("--workdir", type=Path, default=None, help="also time a real fitted+bound head")
    ap.add_argument("--sweep", action="store_true",
                    help="also play every samples/fap/*.fap on the three sample heads (slow)")
    ap.add_argument("--sweep-dir", type=Path, default=None, help="keep the sweep's workdirs here")
    ap.add_argument("--calibrated", type=Path, action="append", default=[],
                    help="a workdir where `faceforge calibrate` ran: its summary goes into the results")
    args = ap.parse_args(argv)
    frames, repeats = (30, 2) if args.quick else (108, 7)
    results = {"target_ms": TARGET_MS, "paper_mesh_d_ms": PAPER_MESH_D_MS, "heads": {}}
    one = ["solver.partitions=1"]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        head, mapping = synthetic_head(Path(tmp) / "a", (44, 58), 25)
        build_s = round(time.perf_counter() - t0, 2)
        rival, _ = synthetic_head(Path(tmp) / "b", (44, 58), 25, one)
        results["heads"]["synthetic_mesh_d"] = {"build_s": build_s,
                                                **measure(head, mapping, frames, repeats, rival)}
    if args.workdir is not None:
        head, mapping = real_head(args.workdir)
        rival, _ = real_head(args.workdir, one)
        results["heads"][str(args.workdir)] = measure(head, mapping, frames, repeats, rival)
    results["threads"] = threads_info()   # after a threaded step: numba names its layer then
    if args.sweep:
        from faceforge.mpeg4 import VISEMES, viseme_track, write_fap

        with tempfile.TemporaryDirectory() as tmp:
            # the eight Xface files, and a generated track of the fourteen visemes (FAP 1)
            speech = Path(tmp) / "visemes_all_fourteen.fap"
            write_fap(speech, viseme_track(list(VISEMES), each=0.24))
            faps = [*sorted((ROOT / "samples" / "fap").glob("*.fap")), speech]
            root = args.sweep_dir if args.sweep_dir is not None else Path(tmp)
            results["sweep"] = sweep(root, list(SAMPLE_HEADS), faps)
    if args.calibrated:
        import json

        results["calibration"] = {}
        for wd in args.calibrated:
            rep = json.loads((wd / "calibrate" / "report.json").read_text())
            results["calibration"][str(wd)] = {
                "summary": rep["summary"], "open_jaw_lip_separation": rep["open_jaw_lip_separation"],
                "rows": [{k: r[k] for k in ("fap", "name", "requested", "achieved_uncalibrated", "achieved",
                                            "relative_error")} for r in rep["rows"]]}
    rows = []
    for name, r in results["heads"].items():
        ms = r["ms_per_frame"]
        rows.append({"head": name, "V": r["skin_vertices"], "F": r["skin_triangles"],
                     "C": r["constraints_skin"] + r["constraints_muscles"], "skull ms": ms["skull"],
                     "muscles ms": ms["muscles"], "skin ms": ms["skin"], "total ms": ms["total"],
                     "cpu ms": r["cpu_ms_per_frame_best"],
                     "1-part total ms": r["one_partition"]["ms_per_frame"]["total"],
                     "ratio": r["one_partition"]["ratio_total"],
                     "target ms": TARGET_MS})
    print_table(rows, title=f"per-frame time, {results['heads']['synthetic_mesh_d']['iterations']} iterations")
    out = write_results("animate", results)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
