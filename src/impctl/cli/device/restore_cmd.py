"""``impctl restore``: the owner's settings back, verified by read-back — from the store's
journal, or from the copy kept next to it (owner-values.json) when the store is unusable.
A register the owner set since impctl last wrote it and read it back (also while impctl was
down) is left as the owner set it (:func:`impctl.controller.restore.restore_entry`); when it
is a heating-curve point, impctl sets no curve until asked again.

Also systemd's ``ExecStopPost=``, so it runs however the daemon ended, with the disk full too:
it needs no free space (what it cannot record, the next start or restore records).
"""

from __future__ import annotations

import asyncio
import sqlite3
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import click

from ...errors import InputError
from .. import cli
from .commands import _load, _setup_logging
from .options import config_option

if TYPE_CHECKING:
    from ...store import JournalEntry


@cli.command("restore")
@config_option
@click.option("--timeout", "timeout_s", type=float, default=60.0, show_default=True,
              help="Keep retrying a lost link this long [s].")
def restore_command(config_path: Path, timeout_s: float) -> None:
    """Restore the journaled owner's settings now (also systemd's ExecStopPost).

    Verified by read-back; needs no free disk space. A register the owner set since impctl's
    last write is left as the owner set it. When the store is unusable (truncated, not a
    database) the copy of the journal kept next to it (owner-values.json) is used; when
    neither is usable, one line names the registers to check by hand.
    """
    from ...controller.restore import owner_kept, unrecorded
    from ...store import Store
    from ...store.restore.owner_file import OWNER_FILE

    cfg = _load(config_path)
    _setup_logging(cfg.log_level, cfg.timezone)
    copy = Path(cfg.state_dir) / OWNER_FILE
    if not cfg.db_path.exists() and not copy.exists():
        click.echo("nothing to restore (no store yet)")
        return
    try:
        store = Store(cfg.db_path, create=False)
    except InputError as exc:
        _restore_from_copy(cfg, copy, str(exc), timeout_s)
        return
    with store:
        try:
            # Entries the copy holds and this database lost (truncated, or an empty file).
            taken = store.recover_journal()
            pending = store.journal_pending()
        except sqlite3.Error as exc:  # opens, but the journal's pages are gone (or full)
            pending = None
            problem = f"{cfg.db_path}: not a usable impctl database: {exc}"
        if pending is not None:
            if not pending:
                click.echo("nothing to restore")
                return
            left = asyncio.run(_restore(cfg, store, timeout_s))
            why = sorted(set(unrecorded(store).values()))
            kept = [e for e in pending if e.id in owner_kept(store)]
    if pending is None:
        _restore_from_copy(cfg, copy, problem, timeout_s)
        return
    if left:
        click.echo("still pending: " + ", ".join(e.register for e in left), err=True)
        sys.exit(1)
    note = ""
    if taken:
        note = (f" ({', '.join(e.register for e in taken)} taken from {copy}: the store had "
                "lost them)")
    if why:
        note += (f"; the store cannot record it ({', '.join(why)}): the next start or impctl "
                 "restore closes the journal")
    click.echo("restored and verified" + note + _kept_note(kept))


def _kept_note(kept: Sequence[JournalEntry]) -> str:
    """"; loop1_setpoint left as the owner set it" for the entries the owner changed since
    impctl's last write (kept, not restored); "" when none."""
    if not kept:
        return ""
    return f"; {', '.join(e.register for e in kept)} left as the owner set it"


def _restore_from_copy(cfg, copy: Path, problem: str, timeout_s: float) -> None:
    """Restore from the owner-values file when the store is unusable; else one line saying
    what to set by hand (exit 1)."""
    from ...controller.restore import owner_kept
    from ...store.restore.owner_file import OwnerValuesJournal

    try:
        journal = OwnerValuesJournal(copy)
    except FileNotFoundError:
        _by_hand(problem, None, f"no copy of the owner's values ({copy} missing)")
    except InputError as exc:
        _by_hand(problem, None, str(exc))
    if not journal.entries:
        click.echo(f"nothing to restore ({problem}; its copy {copy} lists nothing pending "
                   f"since {journal.updated:%Y-%m-%d %H:%M} UTC)")
        return
    left = asyncio.run(_restore(cfg, journal, timeout_s))
    kept = [e for e in journal.entries if e.id in owner_kept(journal)]
    back = [e for e in journal.entries if e not in kept]
    if left:
        _by_hand(problem, back, "the heat pump did not take the owner's values")
    click.echo(f"restored and verified from {copy} (the store is unusable): "
               + (", ".join(_described(e) for e in back) or "nothing") + _kept_note(kept))


def _described(entry) -> str:
    """A journal entry as a person sets it: "register 2187 (loop-1 setpoint) 21.0 °C"."""
    from ...kronoterm.registers import register

    reg = register(entry.address + 1)
    value = entry.raw_value * reg.scale
    shown = f"{value:.1f} {reg.unit}" if reg.unit else f"{value:.0f}"
    return f"register {reg.ma} ({reg.name}) {shown}"


def _by_hand(problem: str, entries, why: str) -> None:
    """One line naming what to put back by hand (the values when known); exit 1."""
    if entries:
        todo = "set by hand: " + ", ".join(_described(e) for e in entries)
    else:
        todo = ("the heat pump may still be off: check register 2187 (loop1_setpoint) and "
                "register 2042 (loop1_mode: 0 off, 1 on, 2 schedule) and set the owner's "
                "values by hand")
    click.echo(f"impctl: {problem}; {why}; {todo}", err=True)
    sys.exit(1)


async def _restore(cfg, journal, timeout_s: float):
    from ...clock import VirtualClock
    from ...controller import restore_all
    from ...controller.restore import on_owner_kept
    from ...daemon.configured import clock_from_config, open_client
    from ...daemon.curve.intent import owner_kept_point
    from ...heatpump import ModbusLinkError

    # a curve point the owner set while impctl's curve was on, kept: the daemon (restarted
    # after this, as systemd does) must not set its curve over it
    on_owner_kept(journal, owner_kept_point(cfg.state_dir))
    clock = clock_from_config(cfg)
    client = open_client(cfg, clock)
    try:
        try:
            await client.connect(max_wait_s=timeout_s)
        except ModbusLinkError as exc:
            click.echo(f"heat pump not reachable: {exc}", err=True)
            return journal.journal_pending()
        # The timeout is in real seconds, whatever clock the nights run on.
        return await restore_all(client, journal, clock=VirtualClock.real(),
                                 timeout_s=timeout_s, retry_s=1.0)
    finally:
        client.close()
