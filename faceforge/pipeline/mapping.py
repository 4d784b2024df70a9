"""Which FAP mapping a playback stage plays (paper §9): the template, the calibrated one.

The template is ``animate.fap_mapping`` (made absolute by the config against the file that set
it); the calibrate stage writes the head's own mapping to ``<workdir>/calibrate/fap_mapping.yaml``.
Every playback stage (animate, expressions, visemes, bake, arkit) plays the calibrated mapping's
FAP entries with the template's presets (:func:`stage_mapping`).
"""

from __future__ import annotations

from pathlib import Path


def mapping_template_path(config) -> Path:
    """``animate.fap_mapping`` (made absolute by the config against the file that set it)."""
    from faceforge.exceptions import ConfigError

    path = Path(str(config.get("animate.fap_mapping")))
    if not path.is_file():
        raise ConfigError(f"animate.fap_mapping: {path} not found")
    return path


def calibrated_mapping_path(workdir) -> Path:
    """The calibrate stage's mapping in ``workdir``."""
    return Path(workdir) / "calibrate" / "fap_mapping.yaml"


def mapping_digest_without_presets(path) -> str:
    """SHA-256 of a FAP mapping file without its presets, the ``expressions`` and ``visemes``
    tables (the calibrate stage's digest of the template: calibration never reads the presets,
    animate takes them from the template, so editing one costs no recalibration). A file that
    is not a YAML mapping is digested whole (the stage then reports it when it runs)."""
    import hashlib
    import json

    import yaml

    from faceforge.io.stagefiles import yaml_safe_load
    from faceforge.pipeline.cache import file_digest

    try:   # libyaml's parser: the same documents, ~0.5 s less per command that keys calibrate
        data = yaml_safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return file_digest(path)
    if not isinstance(data, dict):
        return file_digest(path)
    data.pop("expressions", None)
    data.pop("visemes", None)
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def stage_mapping(ctx):
    """The mapping a playback stage plays and its path: the calibrate stage's (an upstream stage
    of every playback stage), with the presets (expressions and visemes) of the template
    (``animate.fap_mapping``): calibration measures the FAP entries only, and a preset edited
    there (or new in a faceforge release) plays without a recalibration. Another mapping file
    given as the ``animate_mapping`` param (tools, tests; the commands never remember one) plays
    as it is, presets included."""
    from dataclasses import replace

    from faceforge.animation.fap_mapping import load_fap_mapping

    given = ctx.params.get("animate_mapping")
    path = Path(given) if given else ctx.input("calibrate") / "fap_mapping.yaml"
    mapping = load_fap_mapping(path)
    if not given or path.resolve() == calibrated_mapping_path(ctx.workdir).resolve():
        template = load_fap_mapping(mapping_template_path(ctx.config))
        mapping = replace(mapping, expressions=template.expressions, visemes=template.visemes)
    return mapping, str(path)


def playback_mapping(app, command: str) -> Path:
    """The mapping a playback command plays: the calibrate stage's, brought up to date first (a
    cached stage upstream of every playback stage; ``animate.calibrate.enabled: false`` makes it
    the template as it is). Logged as ``<command>: mapping <path>``."""
    calibrated = calibrated_mapping_path(app.workspace.root)
    on = bool(app.config.get("animate.calibrate.enabled"))
    app.log(f"{command}: mapping {calibrated}" + ("" if on else " (uncalibrated template, animate.calibrate.enabled: false)"))
    return calibrated
