"""The commented dump and the reference page: every setting has a meaning, read from the
``#:`` comments beside the defaults; the dump loads back unchanged; the page is up to date."""

from dataclasses import dataclass, fields
from pathlib import Path

import yaml
from click.testing import CliRunner

from gmmap.cli import main
from gmmap.config import Config, load_config
from gmmap.config_doc import (
    MAX_MEANING,
    REFERENCE_PATH,
    REGENERATE,
    commented_dump,
    meanings,
    missing,
    reference,
    sections,
)
from gmmap.options import BuildOptions, LinkOptions, PlaceOptions, SimOptions

ROOT = Path(__file__).resolve().parents[1]


def test_every_setting_has_a_one_line_meaning():
    assert not missing(), (
        f"settings without a meaning: {missing()}; give each a `#:` comment beside its "
        "default (or on the line above it) in gmmap/options.py, fleet_options.py, "
        "ros_options.py or sim_options.py"
    )
    long = {
        f"{name}.{key}": len(text)
        for name, cls in sections().items()
        for key, text in meanings(cls).items()
        if len(text) > MAX_MEANING or not text.strip()
    }
    assert not long, f"meanings longer than {MAX_MEANING} characters (or empty): {long}"


def test_the_meanings_are_the_comments_beside_or_above_the_defaults():
    assert meanings(BuildOptions)["voxel_size"] == "Point-buffer voxel size (m)"
    # Above the field, under plain comments that say why the default is what it is.
    assert meanings(PlaceOptions)["max_confusion"].startswith("Refuse a match unless")
    assert meanings(SimOptions)["sway"].startswith("Carrier roll and pitch")
    assert meanings(LinkOptions)["outages"].startswith("(start, end) seconds")


def test_a_new_setting_without_a_meaning_is_caught():
    @dataclass(frozen=True)
    class Probe:
        plain: int = 1  # a plain comment is not a meaning
        # Nor is one above.
        above: int = 2
        beside: int = 3  #: Beside
        #: Above
        marked: int = 4
        #: First half,
        #: second half
        # why the default is 5
        joined: int = 5

    found = meanings(Probe)
    assert found == {"beside": "Beside", "marked": "Above", "joined": "First half, second half"}
    assert {f.name for f in fields(Probe)} - set(found) == {"plain", "above"}


def test_the_dump_comments_every_section_and_setting():
    text = commented_dump()
    lines = text.splitlines()
    for name, cls in sections().items():
        at = lines.index(f"{name}:")
        assert lines[at - 1].startswith("# "), f"section {name} has no comment"
        for f in fields(cls):
            key = next(i for i in range(at, len(lines)) if lines[i].startswith(f"  {f.name}:"))
            assert lines[key - 1] == f"  # {meanings(cls)[f.name]}", f"{name}.{f.name}"


def test_the_dump_is_the_plain_dump_with_comments_added():
    config = Config(build=BuildOptions(frames_per_submap=7), place=PlaceOptions(top_k=3))
    text = commented_dump(config)
    plain = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    assert plain == config.dump().splitlines()
    assert Config.from_dict(yaml.safe_load(text)) == config


def test_the_cli_dump_loads_back_unchanged(tmp_path):
    result = CliRunner().invoke(main, ["config", "--dump"])
    assert result.exit_code == 0, result.output
    assert result.stdout == commented_dump(Config())
    path = tmp_path / "dumped.yaml"
    path.write_text(result.stdout)
    assert load_config(path) == Config()
    again = CliRunner().invoke(main, ["config", "--config", str(path)])
    assert again.exit_code == 0, again.output
    assert again.stdout == result.stdout


def test_the_reference_page_is_up_to_date():
    page = ROOT / REFERENCE_PATH
    assert page.read_text() == reference(), f"regenerate it: {REGENERATE}"
    text = page.read_text()
    for name, cls in sections().items():
        assert f"\n## {name}\n" in text
        for key, meaning in meanings(cls).items():
            assert f"| `{name}.{key}` |" in text and meaning.replace("|", "\\|") in text
    result = CliRunner().invoke(main, ["config", "--reference"])
    assert result.exit_code == 0 and result.stdout == text
    assert "config-reference.md" in (ROOT / "docs/guide/configuration.md").read_text()
