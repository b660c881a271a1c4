"""Files replaced whole: written beside the target, then renamed over it in one step.

A reader — the daemon, the report, an aggregator's job, the next run after a crash or a full
disk — sees the old file or the new one, never half of one. Pure standard library.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def replacing(target: str | Path, *, mode: int | None = None, fsync: bool = False,
              suffix: str = ".tmp") -> Iterator[Path]:
    """A new, empty file beside ``target`` to write the new content to (yielded as its path).

    When the block ends, the file replaces ``target`` in one rename; when it raises, the file
    is removed and ``target`` is left as it was.

    Parameters
    ----------
    target : the file to replace (its directory must exist)
    mode : the new file's permissions exactly (e.g. ``0o644`` for a file another user reads
        whatever the writer's umask, ``0o600`` for a private one); None: the usual
        ``0o666`` less the umask
    fsync : flush the file to the disk before the rename (a file a restart must find whole)
    suffix : the temporary name's ending (``np.savez`` appends ``.npz`` to any other)
    """
    target = Path(target)
    while True:
        tmp = target.parent / f".{target.name}.{secrets.token_hex(4)}{suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:
            continue
    try:
        try:
            if mode is not None:
                os.fchmod(fd, mode)
        finally:
            os.close(fd)
        yield tmp
        if fsync:
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
