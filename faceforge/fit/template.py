"""The template skull and muscle map, with its muscles built on the template skull (§7).

:func:`load_template` reads ``template.skull`` and ``template.muscle_map`` and builds the muscles
once per process and once per machine (a disk cache keyed by the template files and the
muscle-building source, :func:`template_cache_dir`).
"""

from __future__ import annotations

from pathlib import Path


class Template:
    """The template skull and muscle map, with the muscles built on the template skull.

    skull : :class:`faceforge.anatomy.skull.Skull`; specs : [MuscleSpec]; muscles :
    [(name, rest positions (2hw, 3), faces, hw, thickness fraction)]; layers : {name: layer}.
    """

    def __init__(self, skull, specs, muscles):
        from faceforge.fit.head import FitTemplate
        from faceforge.fit.mouth import point_weights, sheet_weights

        self.skull, self.specs, self.muscles = skull, specs, muscles
        self.layers = {s.name: s.layer for s in specs}
        jaw = skull.jaw
        self.fit_template = FitTemplate(
            skull.cranium, skull.mandible, skull.landmarks,
            {"pitch": (jaw.pitch_point, jaw.pitch_dir), "yaw": (jaw.yaw_point, jaw.yaw_dir),
             "protrusion": (jaw.pitch_point, jaw.protrusion_dir)},
            {s.name: s.points() for s in specs}, {s.name: point_weights(s) for s in specs})
        self.sheet_weights = {s.name: sheet_weights(s.type, s.h, s.w) for s in specs}

    def build_muscles(self, cranium, mandible, warp, shift=None):
        """The template muscles carried by ``warp``, then ``shift`` (the mouth's, weighted per
        particle), with Eq. 5 thickness (fitted skull diagonal)."""
        import numpy as np

        from faceforge.fit.muscles import morph_muscle_meshes

        v = np.vstack([cranium[0], mandible[0]])
        return morph_muscle_meshes(self.muscles, warp, float(np.linalg.norm(np.ptp(v, axis=0))),
                                   shift, self.sheet_weights)


_TEMPLATES: dict = {}
#: bump when the way template muscles are built changes (invalidates the disk cache)
TEMPLATE_CACHE_VERSION = "2"


def template_cache_dir() -> Path:
    """``$FACEFORGE_CACHE`` or ``$XDG_CACHE_HOME/faceforge`` (default ``~/.cache/faceforge``)."""
    import os

    if os.environ.get("FACEFORGE_CACHE"):
        return Path(os.environ["FACEFORGE_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "faceforge"


def load_template(skull_dir, muscle_map) -> Template:
    """The template named by ``template.*``, with its muscles built on the template skull.

    Building the 30 muscles takes seconds, so they are kept per process and on disk
    (:func:`template_cache_dir`, an npz named by the SHA-256 of the template files, the
    muscle-building source files and :data:`TEMPLATE_CACHE_VERSION`); a changed template
    file or muscle-model edit gives a new key.
    """
    import hashlib

    from faceforge.anatomy.muscles.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull

    skull_dir, muscle_map = resolve_template_path(skull_dir), resolve_template_path(muscle_map)
    digest = hashlib.sha256(TEMPLATE_CACHE_VERSION.encode())
    for path in sorted(Path(skull_dir).glob("*")) + [Path(muscle_map)] + _muscle_code_files():
        if path.is_file():
            digest.update(path.name.encode() + path.read_bytes())
    key = digest.hexdigest()[:24]
    if key not in _TEMPLATES:
        skull = load_skull(skull_dir)
        specs = load_muscle_map(muscle_map, skull)
        _TEMPLATES.clear()
        _TEMPLATES[key] = Template(skull, specs, _template_muscles(key, specs, skull))
    return _TEMPLATES[key]


def _muscle_code_files() -> list[Path]:
    """Source files whose code decides the built muscles: they enter the cache key, so an
    edit to the muscle model can never be masked by muscles cached by older code."""
    import faceforge.anatomy.muscles.action_line as action_line
    import faceforge.anatomy.muscles.build as build
    import faceforge.anatomy.muscles.hexmesh as hexmesh
    import faceforge.anatomy.muscles.linear as linear
    import faceforge.anatomy.muscles.muscle as muscle
    import faceforge.anatomy.muscles.muscle_map as muscle_map
    import faceforge.anatomy.muscles.sphincter as sphincter
    import faceforge.fit.muscles as fit_muscles
    import faceforge.geometry.rbf as rbf
    import faceforge.geometry.surface_points as surface_points

    return [Path(m.__file__) for m in (action_line, fit_muscles, hexmesh, muscle, muscle_map, rbf, surface_points,
                                       build, linear, sphincter)]


def _template_muscles(key: str, specs, skull) -> list:
    """[(name, rest, faces, hw, fraction)] from the disk cache, or built and cached."""
    import numpy as np

    from faceforge.anatomy.muscles.build import build_muscles_on
    from faceforge.exceptions import StageError
    from faceforge.io.stagefiles import load_npz, save_npz

    path = template_cache_dir() / f"template-muscles-{key}.npz"
    if path.exists():
        try:
            d = load_npz(path)
            vs, fs = d["vertex_start"], d["face_start"]
            return [(str(n), d["vertices"][vs[i]:vs[i + 1]], d["faces"][fs[i]:fs[i + 1]], int(d["hw"][i]),
                     float(d["fraction"][i])) for i, n in enumerate(d["names"])]
        except (StageError, KeyError, ValueError):
            pass  # a damaged cache file is rebuilt
    fraction = {s.name: s.thickness for s in specs}
    built = [(m.name, m.rest_positions, m.faces, m.topology.h * m.topology.w, fraction[m.name])
             for m in build_muscles_on(specs, skull.cranium, skull.mandible, skull.diagonal)]
    try:
        save_npz(path, names=np.array([b[0] for b in built], dtype=str),
                 vertices=np.vstack([b[1] for b in built]), faces=np.vstack([b[2] for b in built]),
                 vertex_start=np.cumsum([0] + [len(b[1]) for b in built]),
                 face_start=np.cumsum([0] + [len(b[2]) for b in built]),
                 hw=np.array([b[3] for b in built]), fraction=np.array([b[4] for b in built]))
    except OSError:
        pass  # a read-only cache only costs time
    return built


def resolve_template_path(path) -> Path:
    """A template path as given, or relative to the package's repository root."""
    p = Path(path)
    if p.exists() or p.is_absolute():
        return p
    root = Path(__file__).resolve().parents[2]
    return root / p if (root / p).exists() else p
