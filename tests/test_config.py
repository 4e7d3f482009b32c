"""The configuration tree: dump → load, a file's partial tree, flags over the file, typed errors."""

import json

import pytest
import yaml
from click.testing import CliRunner

from conftest import BUNDLED_TUM_SLICE
from gmmap.cli import main
from gmmap.config import Config, ConfigError, load_config
from gmmap.errors import InvalidInputError
from gmmap.options import BuildOptions, PlaceOptions


def test_dump_then_load_gives_the_same_tree(tmp_path):
    config = Config(build=BuildOptions(frames_per_submap=7), place=PlaceOptions(top_k=3))
    path = config.save(tmp_path / "c.yaml")
    assert load_config(path) == config
    assert Config.from_dict(yaml.safe_load(Config().dump())) == Config()


def test_the_cli_dump_is_the_defaults(tmp_path):
    result = CliRunner().invoke(main, ["config", "--dump"])
    assert result.exit_code == 0, result.output
    tree = yaml.safe_load(result.stdout)
    assert list(tree) == [
        "build", "select", "register", "place", "backend", "transport", "link", "robot",
        "security", "station", "ros", "planner", "explore", "sim",
    ]  # fmt: skip
    assert Config.from_dict(tree) == Config()


def test_a_partial_file_keeps_the_other_defaults(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("register:\n  dof: 4\n  local_scales: [0.1, 0]\n")
    config = load_config(path)
    assert config.register.dof == 4 and config.register.local_scales == (0.1, 0.0)
    assert config.build == BuildOptions()


@pytest.mark.parametrize(
    "text",
    [
        "nosuch: {a: 1}\n",
        "build: {nosuch: 1}\n",
        "build: {frames_per_submap: many}\n",
        "build: {frames_per_submap: 0}\n",
        "place: {min_confidence: 2.0}\n",
        "register: {local_scales: 0.1}\n",
        "transport: {connect: [nowhere]}\n",
        "- a list\n",
        "build: {select: 1}\n",
        "{unclosed\n",
    ],
)
def test_a_bad_file_is_a_typed_error(tmp_path, text):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"c\.yaml"):
        load_config(path)


def test_a_flag_overrides_the_file_and_the_effective_tree_is_written(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("build:\n  frames_per_submap: 4\n  n_components: 30\n")
    out = tmp_path / "out"
    args = ["build", str(BUNDLED_TUM_SLICE), "--out", str(out), "--config", str(path)]
    result = CliRunner().invoke(main, [*args, "--components", "20", "--json"])
    assert result.exit_code == 0, result.output
    written = load_config(out / "config.yaml")
    assert written.build.frames_per_submap == 4  # from the file
    assert written.build.n_components == 20  # the flag wins
    submaps = json.loads(result.stdout)["submaps"]
    assert submaps[0]["frames"] == 4  # the file's frames_per_submap
    assert all(s["components_before"] <= 20 for s in submaps)


def test_a_bad_config_file_is_one_error_line(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("build: {covariance: spherical}\n")
    result = CliRunner().invoke(main, ["config", "--config", str(path)])
    assert result.exit_code == 1
    assert result.output.startswith("Error:") and "covariance" in result.output


def test_override_rejects_unknown_keys():
    with pytest.raises(ConfigError, match="no setting"):
        Config().override({"build.nosuch": 1})
    assert Config().override({"build.n_components": None}) == Config()


@pytest.mark.parametrize(
    "bad",
    [{"sweep_s": 0}, {"every_s": -1.0}, {"grpc_port": 0}, {"web_port": 70000},
     {"web_port": True}, {"name": "a/b"}],
)  # fmt: skip
def test_a_wrong_station_setting_is_refused(bad):
    with pytest.raises(InvalidInputError, match="station"):
        Config.from_dict({"station": bad})
