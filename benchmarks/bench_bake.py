"""The ARKit bake on the three sample heads (issue 27). Run:
``python benchmarks/bench_bake.py [--workdirs DIR ...]`` (each DIR a sample fitted and bound, named
after its sample folder: makehuman, ict, mediapipe; default: fitted and bound here).

Per head, through the CLI: ``faceforge bake -o head.glb`` (timed: the stage's own bake seconds,
its Jacobian and solve parts, and the whole command's wall and CPU time, with the load average),
the shapes made and not made (and why), per shape the FAP targets' relative error, the peak
displacement and the folded edges / inverted triangles at full weight, the left/right mirror
agreement. On MakeHuman also the round trips:

* ``animate --fap samples/fap/joy.fap --curves c.csv -o c.glb``: the baked shapes mixed by the
  solved weights against the simulated frames (RMS over the motion), with the head rotation of the
  FAP file (FAPs 48-50, a rigid turn no blendshape makes) and without it;
* ``animate --arkit c.csv --curves back.csv``: the Live Link Face CSV played through the muscles
  and solved again (weights difference), and the CSV's parse identity;

and, when available, the Khronos glTF validator (``GLTF_VALIDATOR_DIR``: a folder where
``npm install gltf-validator`` ran) and Blender (``FACEFORGE_BLENDER_PYTHON``: a Python with bpy;
``tools/blender_shapes_check.py``) on the GLBs. Writes ``benchmarks/results/bake.json``. Not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from _util import write_results  # noqa: E402

SAMPLES = {"makehuman": "makehuman/mh_head_default.obj", "ict": "ict/ict_face_headneck_neutral.obj",
           "mediapipe": "mediapipe/face_model_with_iris.obj"}
CLI = [sys.executable, "-c", "from faceforge.cli import main; main()"]


def cli(work: Path, *args, sets=()):
    """Run faceforge; returns (wall s, CPU s of the child, stdout+stderr)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    cmd = CLI + ["--workdir", str(work)] + [x for s in sets for x in ("--set", s)] + [str(a) for a in args]
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode:
        raise RuntimeError(f"{' '.join(map(str, args))}: {p.stderr.strip()}")
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime), p.stdout + p.stderr


def validator(glb: Path):
    d = os.environ.get("GLTF_VALIDATOR_DIR")
    if not d:
        return None
    js = ("const fs=require('fs'),v=require('gltf-validator');v.validateBytes(new Uint8Array(fs.readFileSync("
          "process.argv[1]))).then(r=>console.log(JSON.stringify({errors:r.issues.numErrors,warnings:"
          "r.issues.numWarnings,infos:r.issues.numInfos,hints:r.issues.numHints,codes:r.issues.messages.map(m=>m.code)"
          ".slice(0,10)})))")
    p = subprocess.run(["node", "-e", js, str(glb)], capture_output=True, text=True, cwd=d)
    return json.loads(p.stdout) if p.returncode == 0 and p.stdout.strip() else {"failed": p.stderr[-300:]}


def blender(glb: Path, frames=None, shapes=None):
    py = os.environ.get("FACEFORGE_BLENDER_PYTHON")
    if not py:
        return {"not_run": "FACEFORGE_BLENDER_PYTHON not set (no Python with bpy here)"}
    args = [py, str(ROOT / "tools" / "blender_shapes_check.py"), str(glb)]
    if frames is not None:
        args += ["--expect-frames", str(frames)]
    if shapes is not None:
        args += ["--shapes", str(shapes)]
    p = subprocess.run(args, capture_output=True, text=True)
    line = [x for x in p.stdout.splitlines() if x.startswith("{")]
    if not line:
        return {"failed": p.stderr[-300:]}
    out = json.loads(line[-1])
    out["shape_keys"] = out["shape_keys"][:3] + ["..."] if len(out["shape_keys"]) > 3 else out["shape_keys"]
    return out


def bake_head(name: str, work: Path, tmp: Path) -> dict:
    load = os.getloadavg()
    glb = tmp / f"{name}.glb"
    wall, cpu, _ = cli(work, "bake", "--force", "-o", glb)
    rep = json.loads((work / "bake" / "report.json").read_text())
    # head units per millimetre of an average adult (the fit's scale): peaks in mm
    mm = json.loads((work / "fit" / "report.json").read_text()).get("units_per_mm")
    shapes = {}
    for n, s in rep["shapes"].items():
        if not s.get("made"):
            shapes[n] = {"made": False, "reason": s["reason"]}
            continue
        shapes[n] = {"error": s.get("error"), "reach": s.get("reach"), "form_error": s.get("form_error"),
                     "verdict": s.get("verdict"), "saturated": s.get("saturated"),
                     "mirrored_pose": bool(s.get("mirrored_pose")), "peak": round(s["peak_displacement"], 5),
                     "peak_mm": round(s["peak_displacement"] / mm, 2) if mm else None,
                     "folded_edges": s["checks"]["folded_edges"],
                     "inverted_triangles": s["checks"]["inverted_triangles"],
                     "approximation": bool(s.get("approximation")),
                     "controls": s.get("controls") or s.get("lids")}
    made = [s for s in shapes.values() if s.get("made", True)]
    errs = [s["error"] for s in made if s["error"] is not None]
    out = {"bake_seconds": rep["bake_seconds"], "bake_cpu_seconds": rep.get("bake_cpu_seconds"), "jacobian_seconds": rep.get("jacobian_seconds"),
           "solve_seconds": rep.get("solve_seconds"), "stage_seconds": rep.get("total_seconds"),
           "command_wall_seconds": round(wall, 1), "command_cpu_seconds": round(cpu, 1),
           "load_average_before": [round(x, 2) for x in load], "made": rep["made"], "not_made": rep["not_made"],
           "fap_error_median": round(float(np.median(errs)), 3) if errs else None,
           "fap_error_max": round(float(np.max(errs)), 3) if errs else None,
           "verdicts": {v: sum(1 for s in made if (s.get("verdict") or "").startswith(v))
                        for v in ("on target", "weak", "approximation")},
           "settle": rep.get("settle_frames"), "poses_settled": rep.get("poses_settled"),
           "frames_simulated": rep.get("frames_simulated"), "statics": rep.get("statics"),
           "symmetric_rig": rep.get("symmetric_rig"),
           "shapes_with_folded_edges": {n: s["folded_edges"] for n, s in shapes.items()
                                        if s.get("folded_edges")},
           "mirror_rel_diff": rep["mirror_rel_diff"], "units_per_mm": mm, "shapes": shapes,
           "validator": validator(glb), "blender": blender(glb, shapes=work / "bake" / "shapes.npz")}
    print(f"{name}: {rep['made']} made, bake {rep['bake_seconds']} s (command {wall:.0f} s wall, {cpu:.0f} s CPU), "
          f"median FAP error {out['fap_error_median']}, folded: {out['shapes_with_folded_edges']}")
    return out


#: ARKit shape -> the MakeHuman expression unit(s) of the same action (tests/data, CC0): their
#: offsets at full strength, measured at the shape's FAP rows, say how far a full action goes
REFERENCE_UNITS = {
    "jawOpen": ("mouth-open",), "mouthSmileLeft": ("mouth-corner-puller",),
    "mouthFrownLeft": ("mouth-depression",), "mouthDimpleLeft": ("mouth-retraction",),
    "mouthStretchLeft": ("neck-platysma",), "mouthUpperUpLeft": ("mouth-elevation",),
    "mouthLowerDownLeft": ("mouth-depression-retraction",), "mouthPucker": ("mouth-pursing",),
    "mouthFunnel": ("mouth-protusion",), "noseSneerLeft": ("nose-left-elevation",),
    "browDownLeft": ("eyebrows-left-down",), "browOuterUpLeft": ("eyebrows-left-extern-up",),
    "browInnerUp": ("eyebrows-left-inner-up", "eyebrows-right-inner-up"),
    "eyeSquintLeft": ("eye-left-slit",),
}


def reference_check(work: Path) -> dict:
    """Per shape of :data:`REFERENCE_UNITS`: its FAP targets (templates/arkit_mapping.yaml) beside
    the MakeHuman unit's motion at the same FDPs (the bake's own probes and FAPU), and what the
    bake achieved (report.json). MakeHuman only (the units are offsets of its vertices)."""
    from faceforge.animation.calibrate_head import calibration_probes
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.animation.rig import BoundHead
    from faceforge.blendshapes.arkit import default_mapping_path, load_arkit_mapping
    from faceforge.blendshapes.rigsolve import probe_observer
    from faceforge.io.config import load_config

    head = BoundHead(work / "fit", work / "bind", load_config(remembered=work / "config.yaml"))
    probes = calibration_probes(load_fap_mapping(work / "calibrate" / "fap_mapping.yaml"), head)
    specs = load_arkit_mapping(default_mapping_path())
    units = np.load(ROOT / "tests" / "data" / "mh_head_expression_units_caucasian.npz")
    names = [str(n) for n in units["names"]]
    got = json.loads((work / "bake" / "report.json").read_text())["shapes"]
    R = np.asarray(head.user_rotation, dtype=float)
    out = {}
    for shape, unit in REFERENCE_UNITS.items():
        faps = [f for f in specs[shape].faps if f in probes]
        frame = head.rest.copy()
        frame[head.user_index] += sum(units["deltas"][names.index(u)].astype(float) for u in unit) @ R.T
        ref = probe_observer(head.rest, [probes[f] for f in faps])(frame[None])[0]
        ach = got.get(shape, {}).get("targets", {})
        out[shape] = {"unit": "+".join(unit),
                      "faps": {str(f): {"target": specs[shape].faps[f], "reference": round(float(r), 1),
                                        "achieved": ach.get(str(f), {}).get("achieved")}
                               for f, r in zip(faps, ref)}}
    return out


def round_trips(work: Path, tmp: Path) -> dict:
    from faceforge.blendshapes.curves import read_weights

    fap = ROOT / "samples" / "fap" / "joy.fap"
    out = {}
    cli(work, "config", "reset")          # the workdir's own overrides would change what is measured
    for label, sets in (("with_head_rotation", ()), ("without_head_rotation", ("animate.head_rotation=false",))):
        _, _, log = cli(work, "animate", "--fap", fap, "--curves", tmp / f"joy_{label}.csv", "-o",
                        tmp / f"joy_{label}.glb", sets=sets)
        line = [x for x in log.splitlines() if "reproduce the simulated frames" in x][-1]
        out[f"joy_curves_{label}"] = line.split("curves: ", 1)[1]
        print(label, line)
    cli(work, "config", "reset")
    csv = tmp / "joy_without_head_rotation.csv"
    names, w, fps = read_weights(csv)
    _, _, log = cli(work, "animate", "--arkit", csv, "--curves", tmp / "back.csv")
    _, w2, fps2 = read_weights(tmp / "back.csv")
    out["live_link_replay"] = {
        "frames": int(len(w)), "fps_in": fps, "fps_back": fps2,
        "weights_max_abs_diff": round(float(np.abs(w - w2).max()), 4),
        "weights_rms_diff": round(float(np.sqrt(np.mean((w - w2) ** 2))), 4),
        "largest_diffs": {names[j]: round(float(np.abs(w[:, j] - w2[:, j]).max()), 3)
                          for j in np.argsort(-np.abs(w - w2).max(axis=0))[:4]},
        "replayed_curves": [x for x in log.splitlines() if "reproduce" in x][-1].split("curves: ", 1)[1]}
    out["bad_takes"] = bad_takes(work, tmp)
    glb = tmp / "joy_without_head_rotation.glb"
    out["joy_glb_validator"] = validator(glb)
    out["joy_glb_blender"] = blender(glb, frames=len(w))
    return out


def bad_takes(work: Path, tmp: Path) -> dict:
    """``animate --arkit`` on bad Live Link takes (issue 27's list and more): {case: {"exit": code,
    "message": its stderr, "written": whether -o was written}} (expected: exit 2, one line naming
    file:line, nothing written)."""
    hdr = "Timecode,BlendShapeCount,EyeBlinkLeft,JawOpen,MouthSmileLeft"
    row = "00:00:00:00.000,3,0.1,0.2,0.3"
    later = "00:00:00:01.000,3,0.1,{},0.3"
    cases = {"unknown_name": hdr.replace("JawOpen", "JawOpn") + "\n" + row + "\n",
             "weight_out_of_range": hdr + "\n" + row + "\n" + later.format("1.5") + "\n",
             "weight_negative": hdr + "\n" + row + "\n" + later.format("-0.2") + "\n",
             "ragged_row": hdr + "\n" + row + "\n00:00:00:01.000,3,0.1,0.2\n",
             "empty_file": "",
             "header_only": hdr + "\n",
             "no_shape_column": "Timecode,BlendShapeCount\n" + row[:17] + "0\n",
             "non_numeric": hdr + "\n" + row + "\n" + later.format("abc") + "\n",
             "empty_cell": hdr + "\n" + row + "\n" + later.format("") + "\n",
             "nan": hdr + "\n" + row + "\n" + later.format("NaN") + "\n",
             "inf": hdr + "\n" + row + "\n" + later.format("inf") + "\n",
             "quote_open": hdr + "\n" + row + "\n" + later.format('"0.2') + "\n",
             "utf16": (hdr + "\n" + row + "\n").encode("utf-16")}
    out = {}
    for case, text in cases.items():
        f = tmp / f"bad_{case}.csv"
        f.write_bytes(text if isinstance(text, bytes) else text.encode())
        target = tmp / f"bad_{case}.pc2"
        p = subprocess.run(CLI + ["--workdir", str(work), "animate", "--arkit", str(f), "-o", str(target)],
                           capture_output=True, text=True)
        out[case] = {"exit": p.returncode, "message": p.stderr.strip().replace(str(tmp) + "/", ""),
                     "written": target.exists()}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdirs", type=Path, nargs="*", default=None)
    ap.add_argument("--round-trip-only", action="store_true", help="keep the heads of the last results.json")
    ap.add_argument("--heads", nargs="*", default=None, help="rebake only these heads (the others, and the "
                    "round trips unless makehuman is one, kept from the last results.json)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        works = {p.name: p for p in (args.workdirs or [])}
        last = json.loads((HERE / "results" / "bake.json").read_text()) if (
            args.round_trip_only or args.heads) else {}
        for name, rel in SAMPLES.items():
            if args.heads and name not in args.heads:
                continue
            if name not in works and not (args.round_trip_only and name != "makehuman"):
                works[name] = tmp / name
                cli(works[name], "fit", ROOT / "samples" / rel)
                cli(works[name], "bind")
        if args.round_trip_only:
            out = {"heads": last["heads"]}
        else:
            out = {"heads": {**last.get("heads", {}),
                             **{n: bake_head(n, works[n], tmp) for n in SAMPLES
                                if n in works and (not args.heads or n in args.heads)}}}
        if "makehuman" in works and not args.round_trip_only:
            out["reference_makehuman"] = reference_check(works["makehuman"])
        elif last.get("reference_makehuman"):
            out["reference_makehuman"] = last["reference_makehuman"]
        if args.heads and "makehuman" not in args.heads:
            out["round_trip_makehuman"] = last.get("round_trip_makehuman")
        elif "makehuman" in works:
            out["round_trip_makehuman"] = round_trips(works["makehuman"], tmp)
        write_results("bake", out)
        return out


if __name__ == "__main__":
    main()
