"""``impctl curve``: the heating curve this house needs, against the one its heat pump runs.

No torch: pandas, scipy and (for ``--plot``) matplotlib, imported inside the command.
"""

from __future__ import annotations

from pathlib import Path

import click

from ...errors import InputError
from .. import cli
from ..checks import SETPOINT_C, bounded, time_zone
from .fit_cmd import _write_json

#: The margin a curve may be given [K]: 0 (the bound itself) to 5 K.
MARGIN_K = (0.0, 5.0)


@cli.command("curve")
@click.option("--nights", "nights_path", default=None,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv with the heating nights: timestamp, t_air, t_out, q_hc and the "
                   "flow and return temperatures t_flow_c, t_return_c; optional "
                   "t_flow_target_c (the heat pump's curve), p_el_w, dhw, defrost, setpoint, "
                   "heating, kind (owner, normal, constrained).")
@click.option("--fit", "fit_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="The house's `impctl fit --json` result: its heat loss and "
                                 "night gain. Without it the heat loss is read from the "
                                 "owner's nights (needs a spread of outdoor temperatures).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the result as JSON (impctl-curve/1) here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Draw the curves (PNG).")
@click.option("--margin-k", default=None, type=float, callback=bounded(MARGIN_K, "K"),
              help="Kelvin of flow temperature kept above the bound of what the house needs "
                   "[default: 1].")
@click.option("--setpoint-c", default=None, type=float, callback=bounded(SETPOINT_C, "°C"),
              help="The room temperature the curve must hold [°C] (default: the owner's "
                   "nights' setpoint, else 21 °C, said so).")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of the nights (22:00–06:00).")
@click.option("--apply", "apply_", is_flag=True,
              help="On a gateway: have the daemon set the curve it keeps (after each fit) on "
                   "the heat pump — an extended controller with its adaptive curve off — and "
                   "watch comfort. With --config, without --nights.")
@click.option("--restore", is_flag=True,
              help="On a gateway: give the owner's heating curve back now and set none until "
                   "--apply again.")
@click.option("--config", "config_path", type=click.Path(path_type=Path),
              default="/etc/impctl/config.toml", show_default=True,
              help="The gateway's configuration (--apply, --restore).")
def curve_cmd(nights_path: Path | None, fit_path: Path | None, json_path: Path | None,
              plot_path: Path | None, margin_k: float | None, setpoint_c: float | None,
              tz: str, apply_: bool, restore: bool, config_path: Path) -> None:
    """The heating curve this house needs, what its heat pump runs, and what lowering it saves.

    From the nights with the heating on: the radiators' or floor's heat output against the
    water temperature (measured), the heat the house needs at each outdoor temperature (the
    fit's heat loss, anchored on the heat the nights show), the lowest flow temperature that
    keeps the room at its setpoint with the margin, as a straight heating curve (two points,
    at −15 and +15 °C outside), against the curve the heat pump runs (its own flow target),
    and the electricity the difference makes over a winter.

    On a gateway, --apply has the daemon set the curve (only when it lowers the running one,
    through the same safe writes as the nights: the owner's points journaled, 20–55 °C, read
    back) and raise it if the room stays short; --restore gives the owner's curve back.
    """
    if apply_ or restore:
        if apply_ and restore:
            raise InputError("--apply and --restore exclude each other")
        if nights_path is not None:
            raise InputError("--apply and --restore act on the gateway's kept curve; give "
                             "--config, not --nights")
        return _on_gateway(config_path, apply_)
    if nights_path is None:
        raise InputError("give --nights NIGHTS.csv (or --apply / --restore with --config)")
    from ...curve import DEFAULT_MARGIN_K, analyse, read_rows
    from ...report.fit_json import read_fit_json
    from ...store.export import refuse_database

    refuse_database(json_path, "--json")
    refuse_database(plot_path, "--plot")
    for out in (json_path, plot_path):
        if out is not None and out.resolve() == nights_path.resolve():
            raise InputError("would overwrite the NIGHTS file", out)
    fit = read_fit_json(fit_path) if fit_path is not None else None
    rows = read_rows(nights_path, tz)
    result = analyse(rows, fit, setpoint_c=setpoint_c,
                     margin_k=DEFAULT_MARGIN_K if margin_k is None else margin_k,
                     source=nights_path)
    for line in result.lines():
        click.echo(line)
    data = result.to_dict()
    if json_path is not None:
        _write_json(json_path, data)
        click.echo(f"JSON written to {json_path}")
    if plot_path is not None:
        from ...curve.plot import plot_curve

        plot_curve(data, plot_path)
        click.echo(f"plot written to {plot_path}")


def _on_gateway(config_path: Path, apply_: bool) -> None:
    """--apply / --restore: the owner's word to the daemon; --restore without a running
    daemon gives the owner's points back itself."""
    from ...config import load_config
    from ...daemon.curve.intent import set_intent
    from ...daemon.curve.state import load_curve
    from ...daemon.locks.store import probe
    from ...heatpump.health import read_health

    cfg = load_config(config_path)
    info = probe(cfg.state_dir)
    daemon = info.running and not info.stale
    if apply_:
        set_intent(cfg.state_dir, True, "impctl curve --apply")
        curve = load_curve(cfg.state_dir)
        generation = ((read_health(cfg.state_dir) or {}).get("generation") or {}).get(
            "generation")
        if curve is None:
            click.echo("no heating curve kept yet: the daemon keeps one after a fit of nights "
                       "with flow and return temperatures, and sets it then")
        else:
            click.echo(curve.get("advice", ""))
            if not curve.get("lowers"):
                click.echo("the kept curve does not lower the running one: nothing is set")
        if generation == "compact":
            click.echo("this is a compact controller (TT3000): it has no heating-curve "
                       "registers, so the curve stays advice — set it in the controller's menu")
        click.echo("recorded: the daemon sets the curve once the heat pump has run its "
                   "present curve points for five minutes, checks that it follows them and "
                   "raises the curve if the rooms stay short; `impctl curve --restore` gives "
                   "your curve back")
        if not daemon:
            click.echo(f"impctl: warning: daemon {info.describe()}; the curve is set when a "
                       "daemon runs on this state directory", err=True)
        return
    set_intent(cfg.state_dir, False, "impctl curve --restore")
    if daemon:
        click.echo("recorded: the running daemon gives your heating curve back at its next "
                   "look and sets none until `impctl curve --apply`")
        return
    import asyncio

    done = asyncio.run(_restore_curve(cfg))
    if done is None:
        click.echo("nothing to restore: impctl has not set a heating curve")
        return
    left, kept = done
    if left:
        click.echo("still pending: " + ", ".join(e.register for e in left), err=True)
        raise SystemExit(1)
    note = f"; {', '.join(kept)} left as you set it" if kept else ""
    click.echo("your heating curve is back, verified by read-back" + note)


async def _restore_curve(cfg):
    """Restore the curve points' pending journal entries (no daemon runs): (the entries still
    pending, the points left as the owner set them since impctl's last write); None when
    there are none."""
    from ...clock import VirtualClock
    from ...controller import restore_all
    from ...controller.restore import owner_kept
    from ...daemon.configured import open_client
    from ...daemon.curve.intent import KEEP
    from ...daemon.locks.heat_pump import HeatPumpLock
    from ...heatpump import ModbusLinkError
    from ...store import Store

    if not cfg.db_path.exists():
        return None
    with Store(cfg.db_path) as store:
        entries = [e for e in store.journal_pending() if e.register in KEEP]
        if not entries:
            return None
        others = {e.register for e in store.journal_pending()} - KEEP
        with HeatPumpLock(cfg.heatpump.link, cfg.state_dir, role="curve --restore"):
            client = open_client(cfg, VirtualClock.real())
            try:
                try:
                    await client.connect(max_wait_s=60.0)
                except ModbusLinkError as exc:
                    click.echo(f"heat pump not reachable: {exc}", err=True)
                    return entries, []
                left = await restore_all(client, store, clock=VirtualClock.real(),
                                         timeout_s=60.0, retry_s=1.0, keep=others)
                return left, [e.register for e in entries if e.id in owner_kept(store)]
            finally:
                client.close()
