"""The ``impctl`` command line: one click group, one module per family of subcommands, by
audience: :mod:`.device` (the gateway's operator) and :mod:`.analysis` (the analyst).

Bad input raises :class:`impctl.errors.InputError`; :func:`main` prints it as one line on
stderr and exits with status 2.
"""

from __future__ import annotations

import sys

import click

from ..errors import InputError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="impctl")
def cli() -> None:
    """Identify a house's 5R1C thermal parameters from night-time heat-pump experiments."""


def _register() -> None:
    # Each subcommand module adds itself to the group; keep imports light (no torch here).
    from .analysis import demo_cmd, fit_cmd, identify_cmds, simulate_cmd  # noqa: F401
    from .device import check_config, commands, restore_cmd  # noqa: F401
    __import__(f"{__name__}.analysis.fleet_cmd")  # impctl fleet fit, impctl flex
    __import__(f"{__name__}.analysis.campaign_cmd")  # impctl campaign next
    __import__(f"{__name__}.analysis.curve_cmd")  # impctl curve
    __import__(f"{__name__}.analysis.season_cmd")  # impctl season
    from .checks import ascii_numbers

    ascii_numbers(cli)  # '２２' is not 22 (click's number types call float() and int())


def run_group(group: click.Group, argv: list[str] | None, prog: str,
              fail: tuple[type[BaseException], ...] = ()) -> None:
    """Run a click group: bad input → one line per problem on stderr and exit status 2;
    exceptions of the types in ``fail`` → one line and exit status 1."""
    try:
        group.main(args=argv, prog_name=prog, standalone_mode=False)
    except InputError as exc:
        for line in str(exc).splitlines():  # a config error may list several problems
            click.echo(f"{prog}: {line}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo(f"{prog}: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except fail as exc:
        click.echo(f"{prog}: {exc}", err=True)
        sys.exit(1)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: run the CLI, turning bad input into one line and exit status 2."""
    _register()
    run_group(cli, argv, "impctl")
