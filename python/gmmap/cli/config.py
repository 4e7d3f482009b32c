"""``gmmap config``: the configuration tree, its defaults or a file's effective values."""

from __future__ import annotations

from pathlib import Path

import click

from gmmap.config import load_config
from gmmap.config_doc import commented_dump, reference


@click.command("config")
@click.option(
    "--dump", is_flag=True, help="Print the effective configuration as YAML, each key explained."
)
@click.option(
    "--config",
    "config_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="A YAML configuration to check and complete with the defaults.",
)
@click.option(
    "--reference",
    "reference_page",
    is_flag=True,
    help="Print the Markdown reference of every setting (docs/guide/config-reference.md).",
)
def command(dump: bool, config_path: Path | None, reference_page: bool) -> None:
    """The configuration every command reads: sections build, select, register, place,
    backend, transport, link, robot, security, station, ros, planner, sim. Without --config:
    the defaults.

    Save the dump, edit what you need (or keep only those keys) and give it to any command
    with --config FILE; its flags override single keys, and every output folder gets the
    effective config.yaml. Each key's comment says what it means.
    """
    if reference_page:
        click.echo(reference(), nl=False)
        return
    config = load_config(config_path)
    if dump or config_path is not None:
        click.echo(commented_dump(config), nl=False)
    else:
        click.echo(click.get_current_context().get_help())
