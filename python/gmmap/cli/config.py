"""``gmmap config``: the configuration tree, its defaults or a file's effective values."""

from __future__ import annotations

from pathlib import Path

import click

from gmmap.config import load_config


@click.command("config")
@click.option("--dump", is_flag=True, help="Print the effective configuration as YAML.")
@click.option(
    "--config",
    "config_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="A YAML configuration to check and complete with the defaults.",
)
def command(dump: bool, config_path: Path | None) -> None:
    """The configuration every command reads: sections build, select, register, place,
    backend, transport, link, robot, security, ros, planner, sim. Without --config: the
    defaults.

    Save the dump, edit what you need (or keep only those keys) and give it to any command
    with --config FILE; its flags override single keys, and every output folder gets the
    effective config.yaml.
    """
    config = load_config(config_path)
    if dump or config_path is not None:
        click.echo(config.dump(), nl=False)
    else:
        click.echo(click.get_current_context().get_help())
