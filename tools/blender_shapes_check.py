"""Open a baked GLB (``faceforge bake -o x.glb`` or ``animate --curves ... -o x.glb``) in real
Blender and report its shape keys and weights animation as JSON.

Run with a Python that has ``bpy`` (``python3.11 -m venv /work/bpy-venv && /work/bpy-venv/bin/pip
install bpy==5.0.1``)::

    /work/bpy-venv/bin/python tools/blender_shapes_check.py x.glb [--expect-frames F] [--shapes shapes.npz]

Prints ``{"blender", "shape_keys" [names, Basis first], "animated_keys", "frame_range",
"keyed_frames", "max_vertex_error"}``: with ``--shapes`` each shape key's vertices (Blender's
Z-up turned back to +Y up) against the baked shape of the same name, in the user's vertex order.
Exit status 1 when a check fails (52 keys + Basis, frame count). Not a test (CI has no Blender).
"""

from __future__ import annotations

import argparse
import json
import sys


def main(argv=None) -> int:
    import bpy
    import numpy as np

    ap = argparse.ArgumentParser()
    ap.add_argument("glb")
    ap.add_argument("--expect-frames", type=int, default=None)
    ap.add_argument("--expect-keys", type=int, default=52)
    ap.add_argument("--shapes", default=None, help="shapes.npz of the bake, to compare vertices")
    args = ap.parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=args.glb)
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    obj = meshes[0]
    keys = obj.data.shape_keys.key_blocks if obj.data.shape_keys else []
    names = [k.name for k in keys]
    out = {"blender": bpy.app.version_string, "file": args.glb, "objects": len(meshes),
           "vertices": len(obj.data.vertices), "shape_keys": names, "n_shape_keys": len(names)}
    action = obj.data.shape_keys.animation_data.action if (
        obj.data.shape_keys and obj.data.shape_keys.animation_data) else None
    if action is not None:
        curves = _fcurves(action)
        frames = sorted({round(p.co[0], 3) for c in curves for p in c.keyframe_points})
        out.update(animated_keys=len(curves), keyed_frames=len(frames),
                   frame_range=[frames[0], frames[-1]] if frames else None)
    if args.shapes:
        d = np.load(args.shapes)
        base = np.array([v.co[:] for v in keys[0].data]) if len(keys) else None
        err = 0.0
        for i, n in enumerate(d["names"]):
            if str(n) in names:
                kb = keys[names.index(str(n))]
                co = np.array([v.co[:] for v in kb.data])
                co = np.stack([co[:, 0], co[:, 2], -co[:, 1]], axis=1)       # Blender Z-up -> +Y up
                want = d["shapes"][i]
                err = max(err, float(np.abs(co - want).max()))
        out["max_vertex_error"] = err
        out["basis_error"] = float(np.abs(np.stack([base[:, 0], base[:, 2], -base[:, 1]], 1) - d["neutral"]).max())
    ok = names[:1] == ["Basis"] and len(names) == args.expect_keys + 1
    if args.expect_frames is not None:
        ok = ok and out.get("keyed_frames") == args.expect_frames
    out["ok"] = bool(ok)
    print(json.dumps(out))
    return 0 if ok else 1


def _fcurves(action):
    """The action's F-curves (Blender 5 keeps them in layered channel bags)."""
    if hasattr(action, "fcurves") and len(getattr(action, "fcurves", [])):
        return list(action.fcurves)
    out = []
    for layer in getattr(action, "layers", []):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", []):
                out.extend(bag.fcurves)
    return out


if __name__ == "__main__":
    sys.exit(main())
