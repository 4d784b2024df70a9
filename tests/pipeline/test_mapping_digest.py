"""The calibrate stage's digest of the FAP mapping (pipeline.mapping.mapping_digest_without_presets):
parsed with libyaml's loader, it must stay the digest of the same document parsed by PyYAML's
pure-Python safe loader (workdirs calibrated before would otherwise recalibrate), and still leave
the presets out."""

from __future__ import annotations

import hashlib
from pathlib import Path

import yaml

from faceforge.pipeline.mapping import mapping_digest_without_presets

ROOT = Path(__file__).resolve().parents[2]


def _pure_python_digest(path) -> str:
    """The digest with the document parsed by ``yaml.safe_load`` (pure Python)."""
    import faceforge.io.stagefiles as sf

    data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    real = sf.yaml_safe_load
    try:
        sf.yaml_safe_load = lambda text: data
        return mapping_digest_without_presets(path)
    finally:
        sf.yaml_safe_load = real


def test_digest_is_the_pure_python_parse_digest():
    path = ROOT / "templates" / "fap_mapping.yaml"
    assert mapping_digest_without_presets(path) == _pure_python_digest(path)


def test_presets_do_not_enter_the_digest(tmp_path):
    text = (ROOT / "templates" / "fap_mapping.yaml").read_text(encoding="utf-8")
    data = yaml.safe_load(text)
    assert "expressions" in data or "visemes" in data
    a = tmp_path / "a.yaml"
    a.write_text(text, encoding="utf-8")
    for key in ("expressions", "visemes"):
        data.pop(key, None)
    b = tmp_path / "b.yaml"
    b.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    assert mapping_digest_without_presets(a) == mapping_digest_without_presets(b)
    assert hashlib.sha256(a.read_bytes()).hexdigest() != hashlib.sha256(b.read_bytes()).hexdigest()
