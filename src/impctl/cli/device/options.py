"""Options shared by the operator's commands."""

from __future__ import annotations

from pathlib import Path

import click

#: Where the gateway's configuration lives when ``--config`` is not given.
DEFAULT_CONFIG = "/etc/impctl/config.toml"

config_option = click.option(
    "--config", "config_path", type=click.Path(path_type=Path), default=DEFAULT_CONFIG,
    show_default=True, help="Daemon configuration (TOML).")
