"""One run at a time in a FLEET dataset: an exclusive lock on a file inside it.

Two runs writing one ``--out`` would each rewrite the manifest over the other's counts, and a
run started beside a ``--resume`` could take the other's half-written batches for its own. The
lock is the kernel's (``flock``): it ends with the process that holds it, however that ends, so
a crashed or killed run leaves nothing to clean up by hand. Local file systems and NFSv4 honour
it; a file system that does not makes the lock a no-op, as it would any advisory lock.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from ...errors import InputError

#: The lock's file inside the dataset; a dotfile, so Parquet readers pass it by.
LOCK_FILE = ".impctl-fleet.lock"


@contextlib.contextmanager
def holding(out: Path) -> Iterator[None]:
    """Hold ``out``'s lock for the block; create ``out`` for it if it is new.

    Raises
    ------
    InputError
        Another process holds the lock (its process id named, where it wrote one). Should the
        block raise and ``out`` be one this call created, ``out`` is removed again when it holds
        nothing but the lock's file: a refused run leaves nothing behind.
    """
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip()
            who = f" (process {holder})" if holder.isdigit() else ""
            raise InputError(f"is being written by another fleet run{who}: wait for it to end, "
                             "or give another --out", out) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        try:
            yield
        except BaseException:
            if created and [p.name for p in out.iterdir()] == [LOCK_FILE]:
                path.unlink(missing_ok=True)
                with contextlib.suppress(OSError):
                    out.rmdir()
            raise
    finally:
        os.close(fd)
