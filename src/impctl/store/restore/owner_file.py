"""The owner's journaled values kept outside the database: ``<state_dir>/owner-values.json``.

The restore journal lives in the SQLite store. An SD card truncated by a power cut takes the
store, and with it the only record of what to put back, while the heat pump may still be off.
So the pending journal entries are mirrored in a small file next to the store, which
``impctl restore`` uses when the store is unusable:

* written whenever the journal changes (before the first write of a night, when an entry is
  restored or closed, when what impctl holds in a register changes); when nothing is pending
  it says so (and when it cannot be rewritten, on a full disk, it is removed: it never names
  a value that is no longer to be restored, nor claims one impctl may have written over);
* beside each entry, what impctl last wrote into its register and read back
  (``confirmed_raw``, null while a write is unconfirmed), so that a restore from the file
  keeps a change the owner made while impctl was down, as one from the store does;
* atomic: a temporary file in the same directory, fsync, rename over the old one, fsync of
  the directory — a power cut leaves the old file or the new one, never half of one;
* checksummed: a SHA-256 over the canonical JSON of its content; a file whose checksum, format
  or values do not hold is never used;
* mode 0640, like the store.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path

from ...atomic import replacing
from ...errors import InputError
from .._times import _dt, _iso, _now
from ..records import JournalEntry

#: The file's name in the state directory.
OWNER_FILE = "owner-values.json"
_FORMAT = "impctl owner values"
_VERSION = 2
#: The fields of an entry by version (a file of version 1, from before ``confirmed_raw``,
#: is read as claiming nothing: the owner's values go back whatever the registers hold).
_FIELDS = {1: ("id", "night_id", "register", "address", "raw_value", "recorded"),
           2: ("id", "night_id", "register", "address", "raw_value", "recorded",
               "confirmed_raw")}
_RAW = (-0x8000, 0xFFFF)
_KEYS = {"format", "version", "updated", "entries", "sha256"}


def _canonical(content: dict) -> bytes:
    return json.dumps(content, sort_keys=True, separators=(",", ":"),
                      ensure_ascii=True).encode()


def write_owner_values(path: Path, entries: Sequence[JournalEntry]) -> None:
    """Atomically replace ``path`` with ``entries`` (the pending journal) and its checksum.

    Raises
    ------
    OSError
        The file could not be written (the old one, if any, is left as it was).
    """
    content = {"format": _FORMAT, "version": _VERSION, "updated": _iso(_now()), "entries": [
        {"id": e.id, "night_id": e.night_id, "register": e.register, "address": e.address,
         "raw_value": e.raw_value, "recorded": _iso(e.recorded),
         "confirmed_raw": e.confirmed_raw} for e in entries]}
    data = {**content, "sha256": hashlib.sha256(_canonical(content)).hexdigest()}
    text = json.dumps(data, indent=1, sort_keys=True).encode() + b"\n"
    with replacing(path, mode=0o640, fsync=True) as tmp:
        tmp.write_bytes(text)
    _fsync_dir(path.parent)


def clear_owner_values(path: Path) -> None:
    """Nothing is pending any more: say so in the file, or remove it when it cannot be
    rewritten (a full disk); never raises."""
    try:
        write_owner_values(path, [])
    except OSError:
        remove_owner_values(path)


def remove_owner_values(path: Path) -> None:
    """Remove the file; never raises. Removing needs no free space (a full disk)."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        return
    except OSError:
        return
    _fsync_dir(path.parent)


def _fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def read_owner_values(path: Path) -> tuple[list[JournalEntry], datetime]:
    """The pending journal entries kept in ``path``, checked, and when it was written.

    Raises
    ------
    FileNotFoundError
        No such file (nothing was pending when it was last written).
    InputError
        Unreadable, not this format, values out of range, or the checksum fails: the file
        is not used.
    """
    try:
        data = json.loads(path.read_bytes())
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as exc:
        raise InputError(f"unreadable ({exc})", path) from None
    if not isinstance(data, dict) or data.get("format") != _FORMAT:
        raise InputError("not an impctl owner-values file", path)
    content = {k: v for k, v in data.items() if k != "sha256"}
    if hashlib.sha256(_canonical(content)).hexdigest() != data.get("sha256"):
        raise InputError("checksum does not match its content; not used", path)
    version = data.get("version")
    if (not isinstance(version, int) or isinstance(version, bool) or version not in _FIELDS
            or set(data) != _KEYS):
        raise InputError(f"unsupported version {version!r}", path)
    fields = _FIELDS[version]
    try:
        updated = _dt(data["updated"])
    except (TypeError, ValueError):
        raise InputError("malformed time", path, "updated") from None
    if not isinstance(data["entries"], list) or updated is None or updated.tzinfo is None:
        raise InputError("malformed content", path)
    out = []
    for i, item in enumerate(data["entries"]):
        if not isinstance(item, dict) or set(item) != set(fields):
            raise InputError("malformed entry", path, f"entry {i + 1}")
        confirmed = item.get("confirmed_raw")
        ok = (isinstance(item["id"], int) and isinstance(item["register"], str)
              and isinstance(item["address"], int) and 0 <= item["address"] <= 0xFFFF
              and _raw(item["raw_value"])
              and (item["night_id"] is None or isinstance(item["night_id"], int))
              and isinstance(item["recorded"], str)
              and (confirmed is None or _raw(confirmed)))
        if not ok:
            raise InputError("malformed entry", path, f"entry {i + 1}")
        try:
            recorded = _dt(item["recorded"])
        except ValueError:
            raise InputError("malformed time", path, f"entry {i + 1}") from None
        out.append(JournalEntry(id=item["id"], night_id=item["night_id"],
                                register=item["register"], address=item["address"],
                                raw_value=item["raw_value"], recorded=recorded, restored=None,
                                confirmed_raw=confirmed))
    return out, updated


def _raw(value: object) -> bool:
    """A register's raw word as the journal keeps it (signed or unsigned 16 bits)."""
    return (isinstance(value, int) and not isinstance(value, bool)
            and _RAW[0] <= value <= _RAW[1])


class OwnerValuesJournal:
    """The restore journal read from the owner-values file, for a restore without the store.

    It answers what :func:`impctl.controller.restore_all` asks of a store
    (``journal_pending``, ``journal_confirmed``, ``journal_mark_restored``,
    ``journal_mark_owner_changed``, ``add_event``); when every entry is restored and verified
    (or kept as the owner set it), the file says that nothing is pending.

    Parameters
    ----------
    path : the owner-values file

    Raises
    ------
    FileNotFoundError, InputError
        As :func:`read_owner_values`.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.entries, self.updated = read_owner_values(self.path)
        self._restored: set[int] = set()

    def journal_pending(self) -> list[JournalEntry]:
        """The file's entries not yet restored by this process."""
        return [e for e in self.entries if e.id not in self._restored]

    def journal_confirmed(self, entry_id: int) -> int | None:
        """What impctl last wrote into ``entry_id``'s register and read back, as the file
        says now (read again: a running night may have written since); None when unknown
        or the file cannot be used."""
        try:
            entries, _ = read_owner_values(self.path)
        except (OSError, InputError):
            return None
        return next((e.confirmed_raw for e in entries if e.id == entry_id), None)

    def journal_mark_restored(self, entry_id: int) -> None:
        """Note an entry restored (after its read-back); the last one removes the file."""
        self._restored.add(entry_id)
        if not self.journal_pending():
            clear_owner_values(self.path)

    def journal_mark_owner_changed(self, entry_id: int, raw_value: int) -> None:
        """The owner set the entry's register (to ``raw_value``) after impctl's last write:
        closed as :meth:`journal_mark_restored` closes one, never restored over."""
        self.journal_mark_restored(entry_id)

    def forget_owner_values(self) -> None:
        """Every entry is restored and verified: the file says nothing is pending."""
        clear_owner_values(self.path)

    def add_event(self, level: str, message: str) -> None:
        """Events have nowhere to go without the store (the log has them)."""
