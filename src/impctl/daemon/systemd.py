"""systemd integration: the sd_notify datagram protocol (READY, STATUS, WATCHDOG, STOPPING).

The protocol is one datagram to the AF_UNIX socket named in ``$NOTIFY_SOCKET`` (a leading ``@``
means the abstract namespace); systemd documents it as a stable interface, so a few lines of
stdlib beat a dependency. Without ``$NOTIFY_SOCKET`` (not run by systemd) every call is a no-op.
"""

from __future__ import annotations

import os
import socket


class Notifier:
    """Send sd_notify messages to systemd.

    Parameters
    ----------
    environ : mapping, optional
        Where to find ``NOTIFY_SOCKET`` and ``WATCHDOG_USEC`` (default ``os.environ``).
    """

    def __init__(self, environ: dict[str, str] | None = None):
        env = os.environ if environ is None else environ
        address = env.get("NOTIFY_SOCKET", "")
        if address.startswith("@"):
            address = "\0" + address[1:]
        self._address = address or None
        usec = env.get("WATCHDOG_USEC", "")
        self.watchdog_interval_s: float | None = int(usec) / 1e6 if usec.isdigit() else None

    @property
    def enabled(self) -> bool:
        """True when running under systemd with a notify socket."""
        return self._address is not None

    def notify(self, **fields: str | int) -> bool:
        """Send ``KEY=value`` lines (e.g. ``READY=1``, ``STATUS=...``); False if not sent."""
        if self._address is None:
            return False
        message = "\n".join(f"{k.upper()}={v}" for k, v in fields.items()).encode()
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
            try:
                sock.connect(self._address)
                sock.sendall(message)
            except OSError:
                return False
        return True

    def ready(self, status: str) -> bool:
        """READY=1 with a status line."""
        return self.notify(ready=1, status=status)

    def status(self, text: str) -> bool:
        """A STATUS= line for ``systemctl status``."""
        return self.notify(status=text)

    def watchdog(self) -> bool:
        """WATCHDOG=1: call after a health check, at least every half interval."""
        return self.notify(watchdog=1)

    def stopping(self, status: str) -> bool:
        """STOPPING=1 with a status line."""
        return self.notify(stopping=1, status=status)
