"""The ``template`` commands: look at the template skull and muscle map (Figs. 6 and 7).

``faceforge template render -o muscles.png [--jaw 0.25] [--contract frontalis_inner_L=0.6]``
builds the muscles of the configured template (``template.skull``,
``template.muscle_map``) on the template skull, simulates the layered system
(§6) to the requested jaw pose and contractions, and draws skull and muscles
front and side, each muscle coloured and labelled. Headless (matplotlib Agg).
Not a stage: it reads only the template and writes only the picture.
"""

from __future__ import annotations

import click

from faceforge.pipeline import register_command


def simulate_template(skull, specs, muscle: dict, solver: dict, contractions: dict,
                      jaw: tuple[float, float, float], frames: int) -> dict:
    """Muscle meshes of the template after ``frames`` steps toward a pose.

    The jaw and the contractions ramp linearly from rest over the first half of
    the frames and hold for the rest, so the layered system (§6) settles.

    Parameters
    ----------
    skull : anatomy.skull.Skull
    specs : [MuscleSpec]
    muscle : the config's ``muscle`` section (``linear.stiffness``, ``sphincter.stiffness``,
        ``damping``)
    solver : the config's ``solver`` section
    contractions : {muscle name: c in [0, 1]}
    jaw : (pitch rad, yaw rad, protrusion template units)
    frames : int, >= 1

    Returns
    -------
    {muscle name: (vertices (n, 3), faces (m, 3))}
    """
    from dataclasses import replace

    from faceforge.anatomy.muscles.build import build_muscles_on
    from faceforge.anatomy.layers import MusculoskeletalSystem
    from faceforge.pbd import SolverSettings

    muscles = build_muscles_on(specs, skull.cranium, skull.mandible, skull.diagonal,
                               {k: dict(muscle[k]["stiffness"]) for k in ("linear", "sphincter")})
    settings = replace(SolverSettings.from_config(solver), damping=float(muscle["damping"]))
    system = MusculoskeletalSystem.from_parts(skull.cranium, skull.mandible, muscles, settings)
    ramp = max(1, frames // 2)
    for i in range(frames):
        s = min(1.0, (i + 1) / ramp)
        system.step({k: s * c for k, c in contractions.items()},
                    skull.jaw_transform(*(s * x for x in jaw)))
    return {m.name: (system.positions(m.name).copy(), system.faces(m.name)) for m in muscles}


def _parse_contractions(values: tuple[str, ...]) -> dict[str, float]:
    out = {}
    for item in values:
        name, sep, value = item.partition("=")
        try:
            c = float(value)
        except ValueError:
            c = float("nan")
        if not sep or not name or not 0.0 <= c <= 1.0:
            raise click.BadParameter(f"{item!r}: expected NAME=C with C in [0, 1]", param_hint="--contract")
        out[name] = c
    return out


@click.group("template", help="Inspect the template skull and muscle map.")
def template_group():
    pass


@template_group.command("render", help="""Draw the template skull and muscle map, front and side.

\b
faceforge template render -o muscles.png
faceforge template render -o open.png --jaw 0.3 --contract zygomaticus_major_L=0.8""")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="PNG to write.")
@click.option("--jaw", "pitch", type=float, default=0.0, show_default=True, help="Jaw opening (pitch, rad).")
@click.option("--yaw", type=float, default=0.0, show_default=True, help="Jaw yaw (rad).")
@click.option("--protrusion", type=float, default=0.0, show_default=True,
              help="Jaw protrusion (template units).")
@click.option("--contract", multiple=True, metavar="NAME=C", help="Contract a muscle (repeatable).")
@click.option("--frames", type=click.IntRange(min=1), default=40, show_default=True,
              help="Simulation frames to reach the pose.")
@click.option("--proxy", is_flag=True, help="Draw contour sheets instead of simulated muscle meshes.")
@click.option("--landmarks", is_flag=True, help="Mark the skull's FDP landmarks.")
@click.pass_obj
def render(app, output, pitch, yaw, protrusion, contract, frames, proxy, landmarks):
    from faceforge.anatomy.muscles.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull
    from faceforge.exceptions import TemplateError
    from faceforge.fit.template import resolve_template_path
    from faceforge.viz.template import render_template

    config = app.config
    skull = load_skull(resolve_template_path(config.get("template.skull")))
    specs = load_muscle_map(resolve_template_path(config.get("template.muscle_map")), skull)
    contractions = _parse_contractions(contract)
    unknown = sorted(set(contractions) - {s.name for s in specs})
    if unknown:
        raise TemplateError(f"--contract: unknown muscle(s) {', '.join(unknown)}; muscles: "
                            + ", ".join(s.name for s in specs))
    jaw = (pitch, yaw, protrusion)
    meshes = None
    if not proxy:
        meshes = simulate_template(skull, specs, config.get("muscle"), config.get("solver"),
                                   contractions, jaw, frames)
    render_template(skull, specs, output, jaw=jaw, contractions=contractions, meshes=meshes,
                    landmarks=landmarks)
    app.log(f"wrote {output}")


register_command(template_group)
