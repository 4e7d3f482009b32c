"""The one command-line entry point, ``gmmap``: one module per command."""

from __future__ import annotations

import sys

import click

from gmmap import __version__
from gmmap.cli import (
    bench,
    build,
    config,
    demo,
    eval,
    explore,
    fleet,
    info,
    merge,
    robot,
    sim,
    station,
)

# The optional dependencies and the extra that installs each (pyproject.toml).
EXTRAS = {
    "zenoh": "fleet",
    "cryptography": "fleet",
    "gtsam": "fleet",
    "rosbags": "io",
    "PIL": "io",
    "evo": "eval",
    "small_gicp": "eval",
    "matplotlib": "eval",
    "sklearn": "eval",
    "rerun": "viz",
}


class _Commands(click.Group):
    """Bad input is the user's to fix: one line naming it, not a traceback; so is a missing
    extra."""

    def invoke(self, ctx: click.Context):
        from gmmap.errors import GmmapError

        try:
            return super().invoke(ctx)
        except (GmmapError, FileNotFoundError) as exc:
            raise click.ClickException(str(exc)) from exc
        except ModuleNotFoundError as exc:
            extra = EXTRAS.get((exc.name or "").split(".")[0])
            if extra is None:
                raise
            raise click.ClickException(
                f"this command needs {exc.name!r}: pip install 'gmmap[{extra}]'"
            ) from exc


@click.group(cls=_Commands, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gmmap")
def main() -> None:
    """gmmap: multi-robot mapping with Gaussian Mixture Model submaps."""


for module in (demo, robot, station, sim, explore, build, merge, eval, bench, info, config, fleet):
    main.add_command(module.command)

if __name__ == "__main__":
    sys.exit(main())
