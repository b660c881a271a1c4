"""The MQTT side of the daemon: one asyncio task that publishes and listens (aiomqtt).

The daemon never awaits anything here: it calls :meth:`MqttBridge.wake` (no I/O) when it has
news, and the bridge pulls the state from its :class:`StateSource` when it publishes. A broker
that is down, slow or refusing the credentials only delays this task: the control loop and the
samples do not wait for it. Reconnects back off (1 s doubling to ``reconnect_max_s``) and an
outage is logged once, when it starts, and once when it ends.
"""

from __future__ import annotations

import asyncio
import json
import logging
import random
import time
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Protocol

import aiomqtt

from ..clock import VirtualClock
from ..errors import InputError
from .commands import COMMANDS, BadCommand, Command, parse_command
from .config import MqttConfig
from .counted import CountedWarnings
from .homeassistant.discovery import (
    OFFLINE,
    ONLINE,
    DeviceIdentity,
    Limits,
    discovery_messages,
    withdrawn_topics,
)
from .homeassistant.payloads import LiveState, curve_payload, fit_payloads
from .takeover import TakeoverWatch
from .tls import SocketErrors, connect_hint
from .tls import context as tls_context

_LOG = logging.getLogger("impctl.mqtt")
#: Longest wait for the bridge's "offline" and disconnect at the daemon's stop [s].
STOP_TIMEOUT_S = 8.0
#: The MQTT client library's own log (paho through aiomqtt).
_CLIENT_LOG = logging.getLogger("impctl.mqtt.client")
#: A publish or subscribe the broker does not acknowledge in this time counts as an outage [s].
_TIMEOUT_S = 10.0
#: How often the fit results are re-read from the store at most [s].
_FIT_CHECK_S = 60.0
_UNSENT = object()


def _disconnected(client: aiomqtt.Client | None) -> asyncio.Future | None:
    # aiomqtt resolves this future in paho's on_disconnect, at the moment of the drop; an
    # operation awaiting the broker (a QoS 1 publish) raises only at its own timeout.
    fut = getattr(client, "_disconnected", None)
    return fut if isinstance(fut, asyncio.Future) else None


def _on_lost(client: aiomqtt.Client, lost: Callable[[], None]) -> None:
    """Call ``lost`` when the connection drops (the session's length ends there)."""
    if (fut := _disconnected(client)) is not None:
        fut.add_done_callback(lambda _f: lost())


def _why_lost(client: aiomqtt.Client | None, exc: aiomqtt.MqttError) -> aiomqtt.MqttError:
    """The connection's own end when an operation timed out after it (its reason code tells a
    session taken over from an outage), else ``exc``."""
    fut = _disconnected(client)
    if fut is not None and fut.done() and not fut.cancelled():
        cause = fut.exception()
        if isinstance(cause, aiomqtt.MqttError) and cause is not exc:
            return cause
    return exc


class StateSource(Protocol):
    """What the daemon offers the bridge."""

    def live(self) -> LiveState:
        """The current state (no I/O beyond the local store)."""

    def identity(self) -> DeviceIdentity:
        """The heat pump as far as known (the controller generation once detected)."""

    async def refresh(self) -> None:
        """Read the heat pump when no night does so (idle); must not raise."""

    def last_fit(self) -> tuple[datetime, list[int], dict] | None:
        """The store's newest fit."""

    def last_curve(self) -> dict | None:
        """The kept heating-curve result (``impctl-curve/1``), or None."""

    def submit(self, command: Command) -> str:
        """Queue a household command through the store; returns a line for the log, or
        raises :class:`BadCommand` when the command may not run now (e.g. a daytime ``now``)."""


class MqttBridge:
    """Publishes impctl's state to a broker in Home Assistant's discovery format.

    Parameters
    ----------
    cfg : MqttConfig
    source : StateSource
    limits : Limits (the trigger's safety limits; also the number entity's range)
    clock : the daemon's clock (the windows of the counted warnings run on it); real time
        when None
    """

    def __init__(self, cfg: MqttConfig, source: StateSource, limits: Limits,
                 clock: VirtualClock | None = None) -> None:
        self.cfg, self.source, self.limits = cfg, source, limits
        clock = clock or VirtualClock.real()
        #: Ignored commands: the first of a kind in full, a flood counted (counted.py).
        self.ignored = CountedWarnings(_LOG, clock.now_s, clock.wall_seconds)
        self._socket_errors = SocketErrors()  # the cause a failed TLS connect leaves there
        self._device: DeviceIdentity | None = None  # as last announced
        self.kind = "constrained"
        self.setpoint_c = limits.default_setpoint_c
        self.connected = False
        self._since = datetime.now(UTC)   # of the current connected/unavailable state
        self._error: str | None = None    # why the broker was last unavailable
        #: Called with :meth:`link_state` whenever it changes (the daemon notes it for
        #: ``impctl status``); must not raise.
        self.on_link_change: Callable[[dict], None] | None = None
        self._wake = asyncio.Event()
        self._rediscover = asyncio.Event()
        self._task: asyncio.Task | None = None
        self._fit_sent: object = _UNSENT
        self._curve_sent: object = _UNSENT
        self._fit_checked = -1e9
        #: ``[inputs]``: an object with ``topics`` (list of str), ``names`` (topic → input)
        #: and ``receive(topic, payload, retained)`` (no I/O, must not raise), or None.
        self.inputs = None

    # -- the daemon's side -----------------------------------------------------------------
    def start(self) -> None:
        """Start the bridge task (returns at once)."""
        _CLIENT_LOG.addFilter(self._socket_errors)
        self._task = asyncio.create_task(self._run(), name="mqtt bridge")

    def link_state(self) -> dict:
        """The broker link for ``impctl status``: ``broker`` (host:port), ``connected``,
        ``since`` (ISO 8601 UTC, of the current state) and ``error`` (why it is down)."""
        return {"broker": f"{self.cfg.host}:{self.cfg.port}", "connected": self.connected,
                "since": self._since.isoformat(timespec="seconds"),
                "error": None if self.connected else self._error}

    def _set_connected(self, connected: bool, error: str | None = None) -> None:
        before = (self.connected, self._error)
        if connected != self.connected:
            self._since = datetime.now(UTC)
        self.connected = connected
        if error is not None:
            self._error = error
        if (self.connected, self._error) != before and self.on_link_change is not None:
            self.on_link_change(self.link_state())

    def wake(self) -> None:
        """New values: publish the state now (never blocks)."""
        self._wake.set()

    async def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> None:
        """Publish ``offline`` (if connected), disconnect and end the task."""
        if self._task is None:
            return
        self._task.cancel()
        try:
            await asyncio.wait_for(self._task, timeout_s)
        except (asyncio.CancelledError, TimeoutError):
            pass
        except Exception as exc:  # noqa: BLE001 - stopping must not fail the daemon's exit
            _LOG.warning("MQTT bridge ended with %r", exc)
        self.ignored.flush()
        _CLIENT_LOG.removeFilter(self._socket_errors)

    # -- connection loop ---------------------------------------------------------------------
    def _client(self) -> aiomqtt.Client:
        cfg = self.cfg
        tls = tls_context(cfg.ca_file, cfg.cert_file, cfg.key_file) if cfg.tls else None
        return aiomqtt.Client(
            cfg.host, cfg.port, username=cfg.username or None, password=cfg.password(),
            identifier=cfg.client_id, keepalive=cfg.keepalive_s, timeout=_TIMEOUT_S,
            will=aiomqtt.Will(f"{cfg.topic}/availability", OFFLINE, qos=1, retain=True),
            tls_context=tls, logger=_CLIENT_LOG)

    async def _run(self) -> None:
        delay, down_since = 1.0, None
        where = f"{self.cfg.host}:{self.cfg.port}"
        watch = TakeoverWatch(self.cfg.client_id)
        quiet = False  # reconnecting after a short session: no line (see takeover.py)
        while True:
            client = None
            try:
                # bound before entering, so that the handlers below can ask it why it ended
                # (None when building it failed, e.g. on an unreadable TLS file)
                client = self._client()
                async with client:
                    self._set_connected(True)
                    watch.started()
                    _on_lost(client, watch.lost)
                    asyncio.get_running_loop().call_later(
                        watch.short_s + 0.2, self._held, watch, where)
                    if quiet:
                        pass
                    elif down_since is None:
                        _LOG.info("MQTT connected to %s as %s (topics %s/…)", where,
                                  self.cfg.client_id, self.cfg.topic)
                    else:
                        _LOG.info("MQTT broker %s back after %.0f s", where,
                                  time.monotonic() - down_since)
                    if not watch.clash:  # in a clash, back off: fewer takeovers
                        delay = 1.0
                    down_since, quiet = None, False
                    await self._session(client)
            except aiomqtt.MqttError as exc:
                exc = _why_lost(client, exc)
                why = self._explain(exc)
                short = watch.ended(exc)
                if short == "new":
                    _LOG.warning("MQTT %s: %s (retrying with back-off up to %g s)", where,
                                 watch.reason, self.cfg.reconnect_max_s)
                if short is not None:
                    # Ended by the broker right after it began: the next connect tells an
                    # outage (logged then) from a takeover (named above once it repeats).
                    self._set_connected(False, watch.reason if watch.clash else why)
                    quiet = True
                else:  # an outage (also after a short session): its lines as usual
                    self._set_connected(False, why)
                    quiet = False
                if short is None and down_since is None:  # one line per outage, not per retry
                    _LOG.warning("MQTT broker %s unavailable: %s (retrying with back-off up "
                                 "to %g s)", where, why, self.cfg.reconnect_max_s)
                    down_since = time.monotonic()
            except (InputError, OSError) as exc:   # the password unreadable: one line, no trace
                quiet = False
                self._set_connected(False, str(exc))
                if down_since is None:
                    _LOG.error("MQTT not connecting: %s (retrying with back-off up to %g s)",
                               exc, self.cfg.reconnect_max_s)
                    down_since = time.monotonic()
            except Exception as exc:  # noqa: BLE001 - MQTT must never take the daemon down
                quiet = False
                self._set_connected(False, f"bridge failed: {exc}")
                if down_since is None:
                    _LOG.exception("MQTT bridge failed; reconnecting with back-off")
                    down_since = time.monotonic()
            finally:
                self._set_connected(False)
            await asyncio.sleep(delay * random.uniform(0.8, 1.2))
            delay = min(delay * 2, self.cfg.reconnect_max_s)

    def _explain(self, exc: aiomqtt.MqttError) -> str:
        """``exc`` in words: with the socket error the client library saw (a TLS alert comes
        only there) and the likely cause, e.g. a TLS client on a plain port."""
        text = str(exc)
        cause = self._socket_errors.take()
        if cause and cause not in text:
            text = f"{text} ({cause})"
        cfg = self.cfg
        hint = connect_hint(text, cfg.host, cfg.port, cfg.tls, cfg.cert_file)
        return f"{text}: {hint}" if hint else text

    def _held(self, watch: TakeoverWatch, where: str) -> None:
        if watch.held():
            _LOG.info("MQTT %s: the session has held for %.0f s; client id '%s' is no longer "
                      "contested", where, watch.short_s, self.cfg.client_id)

    async def _session(self, client: aiomqtt.Client) -> None:
        base = self.cfg.topic
        # Subscribe first: once Home Assistant sees the buttons, pressing them must work.
        # Also with commands off, so that a command sent anyway is logged as refused.
        await client.subscribe(f"{base}/cmd/+", qos=1)
        # Home Assistant says "online" here when it (re)starts: announce again then.
        await client.subscribe(f"{self.cfg.discovery_prefix}/status")
        # The house's own sensors; their retained values arrive at once.
        for topic in (self.inputs.topics if self.inputs is not None else ()):
            await client.subscribe(topic, qos=1)
        await self._announce(client)
        listener = asyncio.create_task(self._listen(client))
        try:
            publisher = asyncio.create_task(self._publish_loop(client))
            done, _ = await asyncio.wait({listener, publisher},
                                         return_when=asyncio.FIRST_COMPLETED)
            for task in (listener, publisher):
                task.cancel()
            for task in done:
                task.result()  # re-raise the MqttError that ended the session
        except asyncio.CancelledError:
            # Stopping: say offline ourselves (a clean disconnect sends no last will).
            try:
                await client.publish(f"{base}/availability", OFFLINE, qos=1, retain=True,
                                     timeout=2.0)
            except Exception:  # noqa: BLE001 - best effort on the way out
                pass
            raise
        finally:
            listener.cancel()

    async def _announce(self, client: aiomqtt.Client) -> None:
        self._device = self.source.identity()
        for topic, payload in discovery_messages(self.cfg, self._device, self.limits):
            await client.publish(topic, payload, qos=1, retain=True)
        for topic in withdrawn_topics(self.cfg):  # commands off: no dead buttons in HA
            await client.publish(topic, b"", qos=1, retain=True)
        await client.publish(f"{self.cfg.topic}/availability", ONLINE, qos=1, retain=True)
        await self._publish_settings(client)
        self._fit_sent = _UNSENT
        self._curve_sent = _UNSENT
        await self._publish_fit(client)

    async def _publish_settings(self, client: aiomqtt.Client) -> None:
        if self.cfg.commands:
            await client.publish(f"{self.cfg.topic}/settings", json.dumps(
                {"kind": self.kind, "setpoint_c": self.setpoint_c}), qos=1, retain=True)

    async def _publish_fit(self, client: aiomqtt.Client) -> None:
        self._fit_checked = time.monotonic()
        fit = self.source.last_fit()
        # What would be sent, not which fit: the morning's season refit rewrites the newest
        # fit's numbers in place (same id, same nights)
        payloads = {name: json.dumps(payload) for name, payload in fit_payloads(fit).items()}
        key = json.dumps(payloads, sort_keys=True)
        if key == self._fit_sent:
            return
        for name, payload in payloads.items():
            await client.publish(f"{self.cfg.topic}/fit/{name}", payload, qos=1, retain=True)
        self._fit_sent = key
        await self._publish_curve(client)

    async def _publish_curve(self, client: aiomqtt.Client) -> None:
        last = getattr(self.source, "last_curve", None)
        payload = json.dumps(curve_payload(last() if last is not None else None),
                             ensure_ascii=False)
        if payload == self._curve_sent:
            return
        await client.publish(f"{self.cfg.topic}/curve", payload, qos=1, retain=True)
        self._curve_sent = payload

    async def _publish_loop(self, client: aiomqtt.Client) -> None:
        idle_s = self.cfg.idle_interval_s
        last_refresh = -1e9
        while True:
            # Again when Home Assistant restarted, or the heat pump's identity became known.
            if self._rediscover.is_set() or self.source.identity() != self._device:
                self._rediscover.clear()
                await self._announce(client)
            state = self.source.live()
            if state.night_state == "idle" and time.monotonic() - last_refresh >= idle_s:
                await self.source.refresh()
                last_refresh = time.monotonic()
                state = self.source.live()
            await client.publish(f"{self.cfg.topic}/state", json.dumps(state.as_json()),
                                 qos=0, retain=False)
            if time.monotonic() - self._fit_checked >= min(idle_s, _FIT_CHECK_S):
                await self._publish_fit(client)
                await self._publish_curve(client)
            self._wake.clear()
            try:
                await asyncio.wait_for(self._wake.wait(), timeout=idle_s)
            except TimeoutError:
                pass

    async def _listen(self, client: aiomqtt.Client) -> None:
        prefix = f"{self.cfg.topic}/cmd/"
        async for message in client.messages:
            topic = str(message.topic)
            payload = message.payload if isinstance(message.payload, bytes) else str(
                message.payload or "").encode()
            if topic == f"{self.cfg.discovery_prefix}/status":
                if payload.strip().lower() == b"online":
                    self._rediscover.set()
                    self.wake()
                continue
            if self.inputs is not None and topic in self.inputs.names:
                self.inputs.receive(topic, payload, bool(message.retain))
                continue
            if not topic.startswith(prefix) and not message.retain:
                continue
            name = topic[len(prefix):] if topic.startswith(prefix) else topic
            if message.retain:
                # A retained command would act again at every reconnect: ignore it.
                self._ignored(name, topic, "retained", "retained messages are not commands")
                continue
            if not self.cfg.commands:
                self._ignored(name, topic, "off", "commands are off (mqtt.commands = false "
                                                  "in the configuration)")
                continue
            try:
                cmd = parse_command(name, payload, self.limits, self.kind, self.setpoint_c)
            except BadCommand as exc:
                self._ignored(name, topic, "malformed", str(exc))
                continue
            if cmd.name in ("night_kind", "night_setpoint"):
                self.kind = cmd.kind or self.kind
                self.setpoint_c = cmd.setpoint_c or self.setpoint_c
                _LOG.info("MQTT setting: triggered nights are %s at %g °C", self.kind,
                          self.setpoint_c)
                await self._publish_settings(client)
            else:
                try:
                    _LOG.info("MQTT command %s: %s", cmd.name, self.source.submit(cmd))
                except BadCommand as exc:
                    self._ignored(name, topic, "refused", str(exc), verb="refused")
                except Exception as exc:  # noqa: BLE001 - a store error must not end MQTT
                    _LOG.error("MQTT command %s could not be queued: %s", cmd.name, exc)
                self.wake()

    def _ignored(self, name: str, topic: str, kind: str, reason: str,
                 verb: str = "ignored") -> None:
        """A command not acted on: one line, or counted in a flood (:mod:`.counted`). The
        keys are bounded: any name that is no command counts as one."""
        known = name in COMMANDS
        subject = topic if known else f"{self.cfg.topic}/cmd/+ (unknown commands)"
        self.ignored.warn((name if known else None, kind), subject, reason,
                          f"MQTT command {topic} {verb}: {reason}")
