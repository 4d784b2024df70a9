"""Config loading, layering and validation messages (file:line: key: expected ..., got ...)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from faceforge.exceptions import ConfigError
from faceforge.io.config import (
    Config,
    _leaf_keys,
    build_config,
    default_config_path,
    load_config,
    load_default,
    parse_sets,
    read_config_file,
    validate_tree,
)


def write(tmp_path: Path, text: str, name: str = "my.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def message(exc_info) -> str:
    return str(exc_info.value)


def test_packaged_default_is_the_repository_file(repo_root):
    assert default_config_path().read_bytes() == (repo_root / "configs" / "default.yaml").read_bytes()


def test_default_is_a_fixed_point_of_validation():
    default = load_default()
    again = validate_tree(default.tree, "default", {}, Path("/"))
    assert again.tree == default.tree


def test_split_pairs_must_be_splittable_arkit_pairs():
    """A typo or an opposite pair (jaw) in bake.split_pairs is refused before any stage runs."""
    for bad in ("[jaw]", "[mouthSmil]"):
        with pytest.raises(ConfigError, match=r"^--set: bake.split_pairs: expected each item to be one of browDown"):
            parse_sets([f"bake.split_pairs={bad}"])
    assert parse_sets(["bake.split_pairs=[mouthSmile, eyeBlink]"]).tree
    assert parse_sets(["bake.split_pairs=[]"]).tree


def test_every_stiffness_in_default_is_checked_against_unit_interval():
    keys = [k for k in _leaf_keys(load_default().tree, leaves_only=True) if ".stiffness." in k]
    assert len(keys) >= 15
    for key in keys:
        with pytest.raises(ConfigError, match=rf"^--set: {key}: expected a number in \[0, 1\], got 1.5$"):
            parse_sets([f"{key}=1.5"])
        assert parse_sets([f"{key}=1"]).tree  # ints are accepted as numbers


def test_error_names_file_line_key_and_expectation(tmp_path):
    path = write(tmp_path, "solver:\n  iterations: 4\n\nskin:\n  stiffness:\n    bending: high\n")
    with pytest.raises(ConfigError) as exc:
        read_config_file(path)
    assert message(exc) == f"{path}:6: skin.stiffness.bending: expected a number in [0, 1], got 'high'"
    assert exc.value.line == 6


def test_unknown_key_suggests_the_nearest(tmp_path):
    path = write(tmp_path, "skin:\n  stiffness:\n    bendin: 0.5\n")
    with pytest.raises(ConfigError) as exc:
        read_config_file(path)
    assert message(exc) == f"{path}:3: skin.stiffness.bendin: unknown key (did you mean skin.stiffness.bending?)"


def test_unknown_top_level_key_without_near_match(tmp_path):
    path = write(tmp_path, "solver:\n  iterations: 3\nzzz_qqq: 1\n")
    with pytest.raises(ConfigError, match=r":3: zzz_qqq: unknown key$"):
        read_config_file(path)


@pytest.mark.parametrize("text, expected", [
    ("solver:\n  iterations: 0\n", "solver.iterations: expected an integer in [1, 1000], got 0"),
    ("solver:\n  iterations: 2.5\n", "solver.iterations: expected an integer in [1, 1000], got 2.5"),
    ("solver:\n  iterations: true\n", "solver.iterations: expected an integer in [1, 1000], got True"),
    ("solver:\n  stiffness_mode: fast\n",
     "solver.stiffness_mode: expected one of paper, iteration_independent, xpbd, got 'fast'"),
    ("fit:\n  refit: 1\n", "fit.refit: expected true or false, got 1"),
    ("solver:\n  damping: .nan\n", "solver.damping: expected a number in [0, 1], got nan"),
    ("skin: 3\n", "skin: expected a mapping, got 3"),
    # a stiffness of 5 was accepted and played
    ("skin:\n  cheek_tether: 5\n", "skin.cheek_tether: expected a number in [0, 1], got 5"),
    ("curves:\n  ridge: -0.1\n", "curves.ridge: expected a number in [0, 1], got -0.1"),
    # a proxy of 50 vertices crashed inside the decimation library with a traceback
    ("fit:\n  simulation_vertices: 50\n", "fit.simulation_vertices: expected 0 (off) or an integer >= 300, got 50"),
    ("fit:\n  simulation_vertices: -1\n", "fit.simulation_vertices: expected 0 (off) or an integer >= 300, got -1"),
    ("skin:\n  stiffness:\n    bending: [1]\n", "skin.stiffness.bending: expected a number in [0, 1], got [1]"),
    # no fraction, no probe: the calibration wrote an empty mapping and said nothing
    ("animate:\n  calibrate:\n    fractions: []\n",
     "animate.calibrate.fractions: expected a list of at least 1 item, got []"),
    ("animate:\n  calibrate:\n    fractions: [0.5, 2]\n",
     "animate.calibrate.fractions: expected each item to be a number in [0.01, 1], got [0.5, 2]"),
])
def test_type_and_range_errors(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as exc:
        read_config_file(path)
    assert message(exc).endswith(expected)
    assert message(exc).startswith(f"{path}:{text.count(chr(10))}:")


def test_first_error_in_file_order_and_count_of_others(tmp_path):
    path = write(tmp_path, "solver:\n  iterations: x\nskin:\n  stiffness:\n    area: 7\n")
    with pytest.raises(ConfigError) as exc:
        read_config_file(path)
    assert message(exc) == f"{path}:2: solver.iterations: expected an integer in [1, 1000], got 'x' (and 1 more)"
    assert [e.line for e in exc.value.all_errors] == [2, 5]


def test_duplicate_key_and_yaml_syntax_errors_have_lines(tmp_path):
    dup = write(tmp_path, "solver:\n  iterations: 3\n  iterations: 4\n", "dup.yaml")
    with pytest.raises(ConfigError, match=r"dup.yaml:3: solver.iterations: duplicate key$"):
        read_config_file(dup)
    bad = write(tmp_path, "solver:\n  iterations: [3\nskin: 1\n", "bad.yaml")
    with pytest.raises(ConfigError, match=r"bad.yaml:3: not valid YAML"):
        read_config_file(bad)


def test_missing_file_and_non_mapping(tmp_path):
    with pytest.raises(ConfigError, match=r"nope.yaml: config file not found$"):
        read_config_file(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match=r"list.yaml:1: expected a mapping of settings, got \[1, 2\]"):
        read_config_file(write(tmp_path, "- 1\n- 2\n", "list.yaml"))
    assert read_config_file(write(tmp_path, "# only a comment\n", "empty.yaml")).tree == {}


def test_set_errors_name_set():
    with pytest.raises(ConfigError) as exc:
        parse_sets(["skin.stiffness.bending=high"])
    assert message(exc) == "--set: skin.stiffness.bending: expected a number in [0, 1], got 'high'"
    with pytest.raises(ConfigError, match=r"^--set: expected key.path=value, got 'solver.iterations'$"):
        parse_sets(["solver.iterations"])
    with pytest.raises(ConfigError, match=r"^--set: solvr: unknown key \(did you mean solver\?\)$"):
        parse_sets(["solvr.iterations=3"])


def test_layers_merge_in_order_and_record_origins(tmp_path):
    remembered = write(tmp_path, "solver:\n  iterations: 5\n  substeps: 2\n", "remembered.yaml")
    user = write(tmp_path, "solver:\n  iterations: 7\n")
    config = load_config(user, ["solver.substeps=3", "skin.stiffness.area=0.5"], remembered=remembered)
    assert config.get("solver.iterations") == 7
    assert config.get("solver.substeps") == 3
    assert config.get("skin.stiffness.area") == 0.5
    assert config.get("skin.stiffness.bending") == load_default().tree["skin"]["stiffness"]["bending"]
    assert config.origins == {"solver.iterations": f"{user}:2", "solver.substeps": "--set",
                              "skin.stiffness.area": "--set"}
    with pytest.raises(KeyError, match="skin.nothing"):
        config.get("skin.nothing")


def test_subtree_access_returns_copies():
    config = build_config([])
    sub = config.get("skin.stiffness")
    sub["bending"] = -1
    assert config.get("skin.stiffness.bending") != -1


def test_yaml_dump_round_trips(tmp_path):
    config = load_config(sets=["solver.iterations=3"])
    assert yaml.safe_load(config.to_yaml()) == config.as_dict()
    assert "iterations: 3  # from --set" in config.to_yaml()
    # the dump is itself a valid config file that reproduces the same configuration
    again = load_config(write(tmp_path, config.to_yaml(annotate=False), "dump.yaml"))
    assert again.as_dict() == config.as_dict()


def test_relative_paths_resolve_against_the_setting_file(tmp_path):
    (tmp_path / "sub").mkdir()
    path = write(tmp_path / "sub", "template:\n  skull: ../my_skull\n")
    assert read_config_file(path).tree["template"]["skull"] == str(tmp_path / "my_skull")
    default_skull = Path(load_default().tree["template"]["skull"])
    assert default_skull.is_absolute() and default_skull.name == "skull"


def test_config_equality_of_values_not_identity():
    a, b = Config({"x": {"y": 1}}), Config({"x": {"y": 1}})
    assert a.as_dict() == b.as_dict() and a.get("x.y") == 1


def test_packaged_templates_link_resolves_like_the_default_paths(repo_root):
    import faceforge

    package = Path(faceforge.__file__).resolve().parent
    # in a checkout faceforge/templates links to templates/; in a wheel it is a copy beside data/
    assert (package / "templates").resolve() == (repo_root / "templates").resolve()
    skull = Path(load_default().tree["template"]["skull"])
    assert skull == (repo_root / "templates" / "skull").resolve()


def test_rules_inferred_from_default_types_and_added_rules(monkeypatch):
    from faceforge.io import config_rules as cfg

    assert cfg.rule_for("x.count", 3) == cfg.Integer(1, 1000)
    assert cfg.rule_for("x.seed", 0) == cfg.Integer(0, 1000)
    assert cfg.rule_for("x.offset", -2) == cfg.Integer(None, 1000)
    assert cfg.rule_for("x.size", 0.5) == cfg.Number(-1e6, 1e6)
    assert cfg.rule_for("x.any.stiffness.k", 0.5) == cfg.Number(0.0, 1.0)
    monkeypatch.setattr(cfg, "RULES", list(cfg.RULES))
    cfg.add_rule("animate.fps", cfg.Number(1, 240))
    with pytest.raises(ConfigError, match=r"^--set: animate.fps: expected a number in \[1, 240\], got 500$"):
        parse_sets(["animate.fps=500"])
    monkeypatch.undo()
    cfg._DEFAULT_CACHE.clear()
    assert parse_sets(["animate.fps=500"]).tree == {"animate": {"fps": 500}}


def test_every_range_rule_holds_without_importing_a_stage_module():
    """The range rules live in faceforge.io.config: a fresh interpreter that imports no stage
    module still rejects out-of-range values of keys the stages read (issue 24)."""
    import os
    import subprocess
    import sys

    code = ("import sys\n"
            "from faceforge.exceptions import ConfigError\n"
            "from faceforge.io.config import load_config\n"
            "bad = ['skin.carry=some', 'muscle.damping=1.5', 'animate.orientation_guard.min_area=0.99',\n"
            "       'animate.skull_guard.collision_reach=0.9', 'fit.orientation=+Z,+Z']\n"
            "caught = 0\n"
            "for s in bad:\n"
            "    try:\n"
            "        load_config(sets=[s])\n"
            "    except ConfigError:\n"
            "        caught += 1\n"
            "assert 'faceforge.pipeline.stages' not in ' '.join(sys.modules), 'a stage module was imported'\n"
            "print(caught)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(__file__).resolve().parents[2],
                         env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "5"
