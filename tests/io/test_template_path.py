"""The one template-path resolver (fit, animation rig and `faceforge template` share it)."""

from pathlib import Path

import faceforge
from faceforge.io.templates import resolve_template_path

PACKAGE = Path(faceforge.__file__).resolve().parent
REPO = PACKAGE.parent


def test_relative_paths_resolve_under_the_repository_then_the_package(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resolve_template_path("templates/muscle_map.yaml") == REPO / "templates/muscle_map.yaml"
    assert resolve_template_path("constants.py") == PACKAGE / "constants.py"   # under the package only
    assert resolve_template_path("no/such/file.yaml") == Path("no/such/file.yaml")


def test_existing_and_absolute_paths_are_kept(tmp_path, monkeypatch):
    (tmp_path / "templates").mkdir()
    (tmp_path / "templates" / "muscle_map.yaml").write_text("{}")
    monkeypatch.chdir(tmp_path)
    assert resolve_template_path("templates/muscle_map.yaml") == Path("templates/muscle_map.yaml")
    missing = tmp_path / "absent.yaml"
    assert resolve_template_path(missing) == missing
