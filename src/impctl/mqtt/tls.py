"""TLS to the broker: the SSL context (the CA, a client certificate), what is wrong with its
files in one line each, and what a failed connection most likely means.

Kept apart from :mod:`.config` so that the configuration check (``impctl check-config``, the
daemon's start) and the bridge build the context the same way: a CA file that is not a
certificate, a client certificate without its key or a key that is encrypted are found
before the first connection, not as a "Connection reset by peer" at night.
"""

from __future__ import annotations

import ipaddress
import logging
import ssl
import stat
from pathlib import Path

#: Ports by convention (IANA): MQTT, MQTT over TLS.
PLAIN_PORT, TLS_PORT = 1883, 8883


class _Encrypted(ssl.SSLError):
    """The key file asked for a passphrase (impctl has none to give)."""


def _no_passphrase() -> bytes:
    # Never OpenSSL's own prompt: the daemon has no terminal, and a prompt would hang it.
    raise _Encrypted


def _ssl_reason(exc: ssl.SSLError) -> str:
    return (exc.reason or str(exc)).replace("_", " ").lower()


def context(ca_file: str = "", cert_file: str = "", key_file: str = "") -> ssl.SSLContext:
    """The client's SSL context: the server verified against ``ca_file`` (empty: the system's
    CAs), and ``cert_file``/``key_file`` presented when the broker asks for a client
    certificate (``key_file`` empty: the key is in ``cert_file``).

    Raises
    ------
    OSError
        A file unreadable or not what it should be (``ssl.SSLError``); :func:`problems` says
        which, in words.
    """
    ctx = ssl.create_default_context(cafile=ca_file or None)
    if cert_file:
        ctx.load_cert_chain(cert_file, key_file or None, password=_no_passphrase)
    return ctx


def problems(ca_file: str = "", cert_file: str = "", key_file: str = "") -> list[tuple[str,
                                                                                      str]]:
    """What keeps the files from making a TLS context: ``(key, problem)`` pairs, ``key`` being
    ``ca_file``, ``cert_file`` or ``key_file``; empty when they load."""
    out: list[tuple[str, str]] = []
    for key, path in (("ca_file", ca_file), ("cert_file", cert_file), ("key_file", key_file)):
        if path and not Path(path).is_file():
            out.append((key, f"no such file: {path}"))
        elif path:
            try:
                Path(path).open("rb").close()
            except OSError as exc:
                out.append((key, f"cannot read {path}: {exc.strerror or exc}"))
    if out:
        return out
    if ca_file:
        try:
            ssl.create_default_context(cafile=ca_file)
        except ssl.SSLError as exc:
            out.append(("ca_file", f"{ca_file} holds no CA certificate OpenSSL can read "
                        f"({_ssl_reason(exc)}): give the broker's CA certificate in PEM form "
                        "(a text file starting '-----BEGIN CERTIFICATE-----')"))
    if cert_file:
        try:
            ssl.create_default_context().load_cert_chain(cert_file, key_file or None,
                                                         password=_no_passphrase)
        except _Encrypted:
            out.append(("key_file" if key_file else "cert_file",
                        f"{key_file or cert_file}: the private key is encrypted with a "
                        "passphrase, which impctl cannot type in: give it the key without one "
                        "(openssl pkey -in KEY -out KEY.plain), readable only by the service "
                        "(chmod 600)"))
        except ssl.SSLError as exc:
            reason = _ssl_reason(exc)
            if "mismatch" in reason:
                out.append(("key_file", f"{key_file} is not the key of the certificate "
                            f"{cert_file} (key values mismatch)"))
            elif key_file:
                out.append(("cert_file", f"{cert_file} and {key_file} do not load as a PEM "
                            f"certificate and its private key ({reason})"))
            else:
                out.append(("cert_file", f"{cert_file} does not load as a PEM certificate "
                            f"with its private key ({reason}); give the key in "
                            "mqtt.key_file if it is in a file of its own"))
    return out


def key_file_warning(cert_file: str, key_file: str) -> str | None:
    """Why the client's private key is too open (group- or world-readable), or None."""
    path = key_file or cert_file
    if not path:
        return None
    try:
        mode = Path(path).stat().st_mode
    except OSError:
        return None  # the check above names the problem
    if mode & (stat.S_IRGRP | stat.S_IROTH | stat.S_IWGRP | stat.S_IWOTH):
        return (f"{path}: the MQTT client's private key is readable by other users (mode "
                f"{stat.S_IMODE(mode):04o}): chmod 600 {path}")
    return None


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine without DNS (``localhost``, 127.0.0.0/8, ::1)."""
    if host.lower() in ("localhost", "localhost.localdomain", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def cleartext_warning(host: str, port: int, tls: bool, username: str) -> str | None:
    """A password that would cross the network unencrypted, in one line (never the password
    itself), or None: TLS off, a user name (and so a password) set, and the broker not on
    this machine."""
    if tls or not username or is_loopback(host):
        return None
    return (f"the MQTT password of '{username}' goes to {host}:{port} in clear text "
            "(mqtt.tls = false): anyone on the network path can read it; set mqtt.tls = true "
            f"(the broker's TLS port, usually {TLS_PORT}) or run the broker on this machine")


#: What an error text says about the TLS handshake (lower case) → its likely cause.
_NOT_TLS = ("connection reset by peer", "eof occurred", "unexpected eof",
            "wrong version number", "record layer failure", "packet length too long")
_CERT_REQUIRED = ("certificate required", "certificate_required")
_CLIENT_CERT_REFUSED = ("unknown ca", "unknown_ca", "bad certificate", "bad_certificate",
                        "certificate unknown", "certificate_unknown", "decrypt error")


def connect_hint(error: str, host: str, port: int, tls: bool, cert_file: str) -> str | None:
    """The likely cause of a failed connection, as advice in one line, or None."""
    text = error.lower()
    where = f"{host}:{port}"
    if tls and any(s in text for s in _CERT_REQUIRED):
        if cert_file:
            return (f"the broker at {where} wants a client certificate but did not take "
                    f"{cert_file}: is it signed by a CA the broker trusts?")
        return (f"the broker at {where} asks for a client certificate: set mqtt.cert_file "
                "and mqtt.key_file")
    if tls and any(s in text for s in _CLIENT_CERT_REFUSED):
        return (f"the broker at {where} refused the client certificate {cert_file or '(none)'}"
                ": is it signed by a CA the broker trusts, and not expired?")
    if tls and ("hostname mismatch" in text or "ip address mismatch" in text):
        return (f"the broker's certificate is not issued for '{host}': set mqtt.host to a "
                "name the certificate names")
    if tls and "certificate verify failed" in text:
        return ("the broker's certificate does not verify against mqtt.ca_file (or the "
                "system's CAs when it is empty): give the CA that signed it")
    if tls and any(s in text for s in _NOT_TLS):
        return (f"does the broker at {where} speak TLS on that port? (plain MQTT is usually "
                f"on {PLAIN_PORT}, MQTT over TLS on {TLS_PORT})")
    if not tls and port == TLS_PORT and ("timed out" in text or "reset" in text):
        return (f"port {TLS_PORT} is usually MQTT over TLS: set mqtt.tls = true (or the "
                f"broker's plain port, usually {PLAIN_PORT})")
    return None


class SocketErrors(logging.Filter):
    """Keeps the MQTT client library's "failed to receive on socket: …" lines out of the log
    and remembers the last one's cause: a TLS alert (a client certificate the broker wants)
    arrives there, while the connect itself only says "Operation timed out". The bridge
    names the cause in its own line, once per outage instead of once per retry."""

    _PREFIXES = ("failed to receive on socket: ", "timeout on socket: ")

    def __init__(self) -> None:
        super().__init__()
        self.last: str | None = None

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        for prefix in self._PREFIXES:
            if message.startswith(prefix):
                self.last = message[len(prefix):]
                return False
        return True

    def take(self) -> str | None:
        """The cause seen since the last call, or None."""
        last, self.last = self.last, None
        return last
