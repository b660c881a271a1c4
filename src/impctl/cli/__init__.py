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


#: The module of each subcommand: ``impctl NAME …`` imports that one alone, so a command does
#: not start by loading every other command's imports (asyncio, the device side …).
COMMAND_MODULES = {
    "check-config": "device.check_config", "daemon": "device.commands",
    "export": "device.commands", "nights": "device.commands", "restore": "device.restore_cmd",
    "status": "device.commands", "trigger": "device.commands",
    "campaign": "analysis.campaign_cmd", "classify": "analysis.identify_cmds",
    "curve": "analysis.curve_cmd", "demo": "analysis.demo_cmd", "fit": "analysis.fit_cmd",
    "fleet": "analysis.fleet_cmd", "flex": "analysis.fleet_cmd", "report": "analysis.demo_cmd",
    "season": "analysis.season_cmd", "simulate": "analysis.simulate_cmd",
    "train": "analysis.identify_cmds",
}


def _register(command: str | None = None) -> None:
    """Add the subcommands to the group: ``command``'s alone when it is one of
    :data:`COMMAND_MODULES`, else every one (help, a typo). Each subcommand module adds itself
    when imported; keep imports light (no torch here)."""
    module = COMMAND_MODULES.get(command or "")
    if module is not None:
        import importlib

        importlib.import_module(f"{__name__}.{module}")
    else:
        from .analysis import (  # noqa: F401
            campaign_cmd,
            curve_cmd,
            demo_cmd,
            fit_cmd,
            fleet_cmd,
            identify_cmds,
            season_cmd,
            simulate_cmd,
        )
        from .device import check_config, commands, restore_cmd  # noqa: F401
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
    args = sys.argv[1:] if argv is None else argv
    _register(args[0] if args else None)
    run_group(cli, argv, "impctl")
