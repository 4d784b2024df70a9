"""Bad input through the CLI on a good workdir (issue 28): every case exits 2 with one line
``faceforge: error: <file>[:line]: <cause>``, and the workdir is byte-identical afterwards
(stage files and the remembered inputs faceforge.yaml and config.yaml).

Each case writes its bad file into the test's own folder (never into the workdir) and
names what the message must contain: the file (or option) and a word of the cause. The
table of cases and their messages is printed by ``python -m tests.reliability.table``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from .conftest import MEDIAPIPE, cli_run, snapshot

GOOD_FAP = (ROOT_FAP := Path(__file__).resolve().parents[2] / "samples" / "fap" / "joy.fap")
MASK_ONE = " ".join(["0"] * 2 + ["1"] + ["0"] * 65)      # FAP 3 (open_jaw) only


def fap_text(rows, fps="25", header_frames=None) -> str:
    """A FAP file giving open_jaw: ``rows`` [(frame number token, value token)]."""
    n = len(rows) if header_frames is None else header_frames
    body = "".join(f"{MASK_ONE}\n{frame} {value}\n" for frame, value in rows)
    return f"2.1 t {fps} {n}\n" + body


def landmarks_text(drop=(), extra="") -> str:
    """The MediaPipe landmark file without the FDPs ``drop``, plus ``extra`` lines."""
    lines = (MEDIAPIPE / "face_model_with_iris.fdp.yaml").read_text().splitlines()
    keep = [ln for ln in lines if not any(ln.strip().startswith(f'"{d}":') for d in drop)]
    return "\n".join(keep) + "\n" + extra


def two_boxes_text() -> str:
    """Two unit cubes side by side, 3 units apart: a file holding two heads."""
    corners = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    quads = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    verts = [f"v {x + dx} {y} {z}" for dx in (0, 3) for x, y, z in corners]
    faces = [f"f {' '.join(str(i + k) for i in q)}" for k in (0, 8) for q in quads]
    return "\n".join(verts + faces) + "\n"


BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n" for p, c in zip("abcdefgh", "bcdefghi"))

# id -> (files {name: text}, args (with {tmp}, {work} and {mesh} filled in), words the one line must hold)
CASES = {
    "mesh is a folder": ({}, ["fit", "{tmp}"], ["{tmp}", "is a directory"]),
    "mesh missing": ({}, ["fit", "{tmp}/nope.obj"], ["nope.obj", "not found"]),
    "mesh malformed": ({"bad.obj": "v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n"}, ["fit", "{tmp}/bad.obj", "--landmarks",
                                                                                  "{lm}"], ["bad.obj:2"]),
    "set then a failing fit": ({"bad.obj": "v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n"},
                               ["--set", "solver.iterations=7", "fit", "{tmp}/bad.obj", "--landmarks", "{lm}"],
                               ["bad.obj:2"]),
    "fap missing": ({}, ["animate", "--fap", "{tmp}/nope.fap"], ["nope.fap", "does not exist"]),
    "workdir is a file": ({"afile": "x"}, ["-w", "{tmp}/afile", "status"], ["afile", "is a file"]),
    "config is a folder": ({}, ["--config", "{tmp}", "status"], ["{tmp}", "directory"]),
    "config alias bomb": ({"bomb.yaml": BOMB}, ["--config", "{tmp}/bomb.yaml", "status"],
                          ["bomb.yaml", "alias"]),
    "config nested deep": ({"deep.yaml": "solver: " + "[" * 200 + "]" * 200 + "\n"},
                           ["--config", "{tmp}/deep.yaml", "status"], ["deep.yaml", "nest"]),
    "config 5000 digits": ({"digits.yaml": "solver:\n  iterations: " + "9" * 5000 + "\n"},
                           ["--config", "{tmp}/digits.yaml", "status"], ["digits.yaml", "digits"]),
    "config huge float": ({"huge.yaml": "solver:\n  damping: 1e400\n"}, ["--config", "{tmp}/huge.yaml", "status"],
                          ["huge.yaml:2", "solver.damping"]),
    "set iterations 1e9": ({}, ["--set", "solver.iterations=1e9", "animate", "--expression", "joy"],
                           ["--set", "solver.iterations", "1000"]),
    "set expression_seconds 1e9": ({}, ["--set", "animate.expression_seconds=1.0e+9", "animate",
                                        "--expression", "joy"], ["--set", "animate.expression_seconds"]),
    "set huge int": ({}, ["--set", "solver.iterations=" + "9" * 5000, "status"], ["--set", "solver.iterations"]),
    "set deep nesting": ({}, ["--set", "solver.damping=" + "[" * 300 + "]" * 300, "status"],
                         ["--set", "solver.damping"]),
    "set alias bomb": ({}, ["--set", "solver.damping=" + BOMB.replace("\n", "; ").replace("; ", ", ", 0)[:0]
                            + "{a: &a [1,1,1,1,1,1,1,1], b: &b [*a,*a,*a,*a,*a,*a,*a,*a], "
                              "c: &c [*b,*b,*b,*b,*b,*b,*b,*b], d: &d [*c,*c,*c,*c,*c,*c,*c,*c], "
                              "e: &e [*d,*d,*d,*d,*d,*d,*d,*d], f: &f [*e,*e,*e,*e,*e,*e,*e,*e], "
                              "g: [*f,*f,*f,*f,*f,*f,*f,*f]}", "status"], ["--set", "solver.damping", "alias"]),
    "fap frame beyond int64": ({"f.fap": fap_text([("99999999999999999999", "10")])},
                               ["animate", "--fap", "{tmp}/f.fap"], ["f.fap:3", "frame number"]),
    "fap frame 1e300": ({"f.fap": fap_text([("0", "1"), ("1e300", "10")])}, ["animate", "--fap", "{tmp}/f.fap"],
                        ["f.fap:5", "frame number"]),
    "fap frame differences overflow": ({"f.fap": fap_text([("-9223372036854775807", "1"),
                                                           ("9223372036854775807", "2")])},
                                       ["animate", "--fap", "{tmp}/f.fap"], ["f.fap:3", "frame number"]),
    "fap fps 1e-300": ({"f.fap": fap_text([("0", "1")], fps="1e-300")}, ["animate", "--fap", "{tmp}/f.fap"],
                       ["f.fap:1", "fps"]),
    "fap fps 1e300": ({"f.fap": fap_text([("0", "1")], fps="1e300")}, ["animate", "--fap", "{tmp}/f.fap"],
                      ["f.fap:1", "fps"]),
    "fap truncated": ({"f.fap": fap_text([("0", "1")]) + MASK_ONE + "\n"}, ["animate", "--fap", "{tmp}/f.fap"],
                      ["f.fap", "truncated"]),
    "fap binary junk": ({"f.fap": "\x00\x01\x02 garbage\n"}, ["animate", "--fap", "{tmp}/f.fap"], ["f.fap"]),
    "preview unwritable": ({}, ["animate", "--expression", "joy", "--preview", "{tmp}/no/such/p.png"],
                           ["p.png", "does not exist"]),
    "output unknown suffix": ({}, ["animate", "--expression", "joy", "-o", "{tmp}/a.xyz"], ["a.xyz"]),
    # (a missing folder used to fail after the whole simulation, with "cannot write here")
    "output folder missing": ({}, ["animate", "--expression", "joy", "-o", "{tmp}/no/a.pc2"],
                              ["a.pc2", "-o: folder", "does not exist"]),
    "obj sequence parent missing": ({}, ["animate", "--expression", "joy", "-o", "{tmp}/no/frames"],
                                    ["frames", "-o: folder", "does not exist"]),
    # (a landmark file without pupils is no longer bad input: the landmarks stage detects the
    # missing FDPs; the fit still refuses landmarks it cannot measure the FAP units on)
    "landmarks huge int": ({"lm.yaml": 'landmarks:\n  "2.1": {vertex: 99999999999999999999}\n'},
                           ["fit", "{mesh}", "--landmarks", "{tmp}/lm.yaml"], ["lm.yaml", "vertex id"]),
    "landmarks huge float": ({"lm.yaml": 'landmarks:\n  "2.1": {position: [1e400, 0, 0]}\n'},
                             ["fit", "{mesh}", "--landmarks", "{tmp}/lm.yaml"], ["lm.yaml", "finite"]),
    "landmarks unhashable key": ({"lm.yaml": "landmarks:\n  ? [1, 2]\n  : {vertex: 1}\n"},
                                 ["fit", "{mesh}", "--landmarks", "{tmp}/lm.yaml"], ["lm.yaml:2", "key"]),
    "landmarks nested deep": ({"lm.yaml": "landmarks: " + "[" * 3000 + "]" * 3000 + "\n"},
                              ["fit", "{mesh}", "--landmarks", "{tmp}/lm.yaml"], ["lm.yaml", "nest"]),
    "landmarks 5000 digits": ({"lm.yaml": 'landmarks:\n  "2.1": {vertex: ' + "9" * 5000 + "}\n"},
                              ["fit", "{mesh}", "--landmarks", "{tmp}/lm.yaml"], ["lm.yaml:2", "more than 100 digits"]),
    "landmarks alias bomb": ({"lm.yaml": BOMB}, ["fit", "{mesh}", "--landmarks", "{tmp}/lm.yaml"],
                             ["lm.yaml", "alias"]),
    "landmarks json deep": ({"lm.json": "[" * 100000 + "]" * 100000},
                            ["fit", "{mesh}", "--landmarks", "{tmp}/lm.json"], ["lm.json", "nested"]),
    "landmarks csv bad number": ({"lm.csv": "fdp,vertex,x,y,z\n2.1,1,0,0,abc\n"},
                                 ["fit", "{mesh}", "--landmarks", "{tmp}/lm.csv"], ["lm.csv:2", "2.1"]),
    "landmarks unknown format": ({"lm.txt": "x"}, ["fit", "{mesh}", "--landmarks", "{tmp}/lm.txt"],
                                 ["lm.txt", "format"]),
    # ARKit takes (animate --arkit) and curves: read before anything runs
    "arkit csv NUL byte": ({"t.csv": "jawOpen\n0.1\x00\n"}, ["animate", "--arkit", "{tmp}/t.csv"],
                           ["t.csv:2", "not a number"]),
    "arkit csv weight nan": ({"t.csv": "jawOpen\nnan\n"}, ["animate", "--arkit", "{tmp}/t.csv"],
                             ["t.csv:2", "outside [0, 1]"]),
    # a header of no shape (was played as a take of no weights: the stages ran), a quote left open
    # (was read as closed), a UTF-16 export (was named without its line)
    "arkit csv no shape column": ({"t.csv": "Timecode,BlendShapeCount\n00:00:00:00.000,0\n"},
                                  ["animate", "--arkit", "{tmp}/t.csv"], ["t.csv:1", "no blendshape column"]),
    "arkit csv quote open": ({"t.csv": 'jawOpen\n0.1\n"0.2\n'}, ["animate", "--arkit", "{tmp}/t.csv"],
                             ["t.csv:3", "not a CSV file"]),
    "arkit csv utf-16": ({"t.csv": "jawOpen\n0.1\n".encode("utf-16")}, ["animate", "--arkit", "{tmp}/t.csv"],
                         ["t.csv:1", "not UTF-8"]),
    "arkit csv timecodes at 24000 fps": ({"t.csv": "Timecode,jawOpen\n" + "".join(
        f"00:00:00:00.{k:03d},0.1\n" for k in range(4))}, ["animate", "--arkit", "{tmp}/t.csv"],
        ["t.csv", "frame rate"]),
    "arkit json nested deep": ({"t.json": "[" * 100000 + "]" * 100000}, ["animate", "--arkit", "{tmp}/t.json"],
                               ["t.json", "nested"]),
    "arkit json 5000 digits": ({"t.json": '{"names": ["jawOpen"], "weights": [[' + "9" * 5000 + "]]}"},
                               ["animate", "--arkit", "{tmp}/t.json"], ["t.json", "digits"]),
    "arkit json fps text": ({"t.json": '{"names": ["jawOpen"], "weights": [[0.1]], "fps": "abc"}'},
                            ["animate", "--arkit", "{tmp}/t.json"], ["t.json", "numbers"]),
    "arkit json fps 1e-300": ({"t.json": '{"names": ["jawOpen"], "weights": [[0.1]], "fps": 1e-300}'},
                              ["animate", "--arkit", "{tmp}/t.json"], ["t.json", "frame rate"]),
    "arkit json names not text": ({"t.json": '{"names": [5], "weights": [[0.1]]}'},
                                  ["animate", "--arkit", "{tmp}/t.json"], ["t.json", "names"]),
    "arkit json ragged weights": ({"t.json": '{"names": ["jawOpen"], "weights": [[0.1], [0.1, 0.2]]}'},
                                  ["animate", "--arkit", "{tmp}/t.json"], ["t.json", "numbers"]),
    "curves unknown suffix": ({}, ["animate", "--fap", str(GOOD_FAP), "--curves", "{tmp}/c.txt"],
                              ["c.txt", "--curves"]),
    "curves folder missing": ({}, ["animate", "--fap", str(GOOD_FAP), "--curves", "{tmp}/no/c.csv"],
                              ["c.csv", "--curves", "does not exist"]),
    "curves is a folder": ({}, ["animate", "--fap", str(GOOD_FAP), "--curves", "{tmp}"],
                           ["--curves"]),
    "bake output folder missing": ({}, ["bake", "-o", "{tmp}/no/x.glb"], ["x.glb", "does not exist"]),
    "bake output unknown suffix": ({}, ["bake", "-o", "{tmp}/x.xyz"], ["x.xyz", ".glb"]),
    "bake mapping malformed": ({"m.yaml": "shapes: [\n"}, ["bake", "--mapping", "{tmp}/m.yaml"], ["m.yaml:2", "YAML"]),
    "landmarks of a malformed mesh": ({"bad.obj": "v 1 2\nf 1 2 3\n"}, ["landmarks", "{tmp}/bad.obj"],
                                      ["bad.obj:1", "OBJ"]),
    "landmarks of a mesh with two heads": ({"two.obj": two_boxes_text()}, ["landmarks", "{tmp}/two.obj"],
                                           ["two.obj", "2 separate head-sized pieces"]),
    "fit of a mesh with two heads": ({"two.obj": two_boxes_text()}, ["fit", "{tmp}/two.obj"],
                                     ["two.obj", "2 separate head-sized pieces"]),
    "landmarks output is the mesh": ({}, ["landmarks", "{mesh}", "-o", "{mesh}"], ["is your mesh"]),
    "landmarks output folder missing": ({}, ["landmarks", "{mesh}", "-o", "{tmp}/no/x.yaml"],
                                        ["x.yaml", "does not exist"]),
    # outputs inside the workdir's own files (a --preview overwrote fit/fit.png; a file added to a
    # stage folder was deleted with the stage's next run)
    "preview into a stage folder": ({}, ["animate", "--expression", "joy", "--preview", "{work}/fit/fit.png"],
                                    ["fit.png", "--preview", "stage folder fit/"]),
    "output into a stage folder": ({}, ["animate", "--expression", "joy", "-o", "{work}/bind/x.pc2"],
                                   ["x.pc2", "-o", "stage folder bind/"]),
    "sheet into a stage folder": ({}, ["expressions", "-o", "{work}/fit/x.png"], ["x.png", "stage folder fit/"]),
    "landmarks output is faceforge.yaml": ({}, ["landmarks", "{mesh}", "-o", "{work}/faceforge.yaml"],
                                           ["faceforge.yaml", "workdir's own"]),
    "mesh with a NaN vertex": ({"nan.obj": "v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 1 1\nf 1 2 3\nf 1 3 4\n"},
                               ["fit", "{tmp}/nan.obj", "--landmarks", "{lm}"], ["nan.obj", "NaN"]),
    "batch manifest name escapes": ({"m.yaml": "heads:\n  - mesh: x.obj\n    name: ../../etc\n"},
                                    ["batch", "{tmp}/m.yaml", "--out", "{tmp}/out", "--expression", "joy"],
                                    ["m.yaml:3", "name"]),
    "batch manifest mesh not text": ({"m.yaml": "heads:\n  - mesh: 5\n"},
                                     ["batch", "{tmp}/m.yaml", "--out", "{tmp}/out", "--expression", "joy"],
                                     ["m.yaml:2", "mesh"]),
    "calibrate set of the wrong type": ({}, ["--set", "animate.calibrate=5", "calibrate"],
                                        ["--set", "animate.calibrate"]),
    "unknown stage": ({}, ["run", "nosuchstage"], ["nosuchstage"]),
    "unknown expression": ({}, ["animate", "--expression", "nosuch"], ["nosuch"]),
    "two motion sources": ({}, ["animate", "--expression", "joy", "--fap", str(GOOD_FAP)], ["exactly one"]),
    "unknown option": ({}, ["animate", "--no-such-option"], ["--no-such-option"]),
    "set without value": ({}, ["--set", "solver.damping", "status"], ["--set", "key.path=value"]),
    "set unknown key": ({}, ["--set", "solver.nosuch=1", "status"], ["--set", "solver.nosuch"]),
}


def _fill(text: str, tmp: Path, work: Path) -> str:
    return (text.replace("{tmp}", str(tmp)).replace("{work}", str(work))
            .replace("{mesh}", str(MEDIAPIPE / "face_model_with_iris.obj"))
            .replace("{lm}", str(MEDIAPIPE / "face_model_with_iris.fdp.yaml")))


def run_case(name: str, tmp: Path, work: Path):
    """Run case ``name`` on ``work``; returns (result, expected words)."""
    files, args, words = CASES[name]
    for fname, text in files.items():
        if isinstance(text, bytes):
            (tmp / fname).write_bytes(text)
        else:
            (tmp / fname).write_text(text, encoding="utf-8")
    args = [_fill(a, tmp, work) for a in args]
    if args[0] != "-w":
        args = ["-w", str(work)] + args
    return cli_run(*args), [_fill(w, tmp, work) for w in words]


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_is_one_line_exit_2_and_the_workdir_is_untouched(name, fitted, tmp_path):
    case_dir = tmp_path / "case"
    case_dir.mkdir()
    before = snapshot(fitted)
    result, words = run_case(name, case_dir, fitted)
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.exception)
    lines = result.stderr.splitlines()
    errors = [ln for ln in lines if ln.startswith("faceforge: error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0], result.stderr
    assert "Traceback" not in result.stderr and len(errors[0]) < 2100
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert snapshot(fitted) == before
