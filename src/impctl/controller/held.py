"""What impctl holds in the registers a night (or the heating curve's watch,
:mod:`impctl.daemon.curve.watch`) writes: the value it last wrote into each and read back.

A night tells the owner's change from its own by it (:mod:`.owner`), and so does its restore
(:func:`.restore.restore_entry`). The process may die mid-night (SIGKILL, a power cut) and
the owner change a register before anything restarts, so the value is also kept beside the
register's journal entry, in the store and its copy (``owner-values.json``): the restart's
restore and ``impctl restore`` then keep the owner's change as the night's own restore would.

A write gives up the claim first, in memory and beside the entry, and claims its value again
only once read back: a write that lands unseen (the link drops, the process dies) leaves
impctl claiming nothing there, so the restore puts the owner's value back whatever it finds.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping

from ..heatpump import WriteResult
from ..kronoterm.registers import register
from ..store import Store
from .owner import JOURNAL_NAMES


class Held(dict[int, float]):
    """Register number → the value impctl last wrote there and read back (physical unit), for
    one night (or one setting of the curve); its journal entries (register → entry id) keep it
    beside them.

    Parameters
    ----------
    store : the store holding the night's journal (None: kept in memory only)
    entries : register number → its journal entry id
    values : register number → the value read there when the night journaled it
    """

    def __init__(self, store: Store | None = None, entries: Mapping[int, int] | None = None,
                 values: Mapping[int, float] | None = None) -> None:
        super().__init__(values or {})
        self.store = store
        self.entries = dict(entries or {})

    async def write(self, ma: int, write: Callable[[], Awaitable[WriteResult]]) -> WriteResult:
        """Make ``write()`` (a safe-client write of register ``ma``) and hold what it read back.

        Raises
        ------
        sqlite3.Error
            The store cannot record that impctl gives the register up: nothing is written
            (the value kept beside the entry still holds), the night ends.
        """
        self.pop(ma, None)
        self._keep(ma, None)
        result = await write()
        self[result.ma] = result.read_back
        self._keep(result.ma, round(result.read_back / register(result.ma).scale))
        return result

    def by_name(self) -> dict[str, float]:
        """The values by journal name (what :func:`.restore.restore_all` takes)."""
        return {name: self[ma] for ma, name in JOURNAL_NAMES.items() if ma in self}

    def _keep(self, ma: int, raw: int | None) -> None:
        entry = self.entries.get(ma)
        if self.store is not None and entry is not None:
            self.store.journal_confirm(entry, raw)
