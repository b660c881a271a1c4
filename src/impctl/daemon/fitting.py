"""The fit after every valid night, in subprocesses: ``impctl export`` → ``impctl fit`` →
``impctl curve`` (the heating curve the house needs, kept in the state directory when the
nights hold what it needs) and, in adaptive mode, ``impctl campaign next`` (the predictions for
the next night).

The daemon never imports torch, scikit-learn or pandas; only the JSON results come back. Each
fit is stored with the number of valid nights it used, its predictions with it.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import sys
from pathlib import Path

from ..config import Config
from ..store import Store
from .curve.state import keep_curve
from .nights.adaptive import forecast

_LOG = logging.getLogger("impctl.daemon")
_KINDS = ("constrained", "normal")
#: Niceness added to the fit's subprocesses.
FIT_NICE = 10


def fit_ready(store: Store) -> str | None:
    """None when a fit can run on the valid nights; else why not (one plain sentence)."""
    valid = store.nights(valid=True)
    missing = [k for k in _KINDS if not any(n.kind == k for n in valid)]
    if missing:
        return f"the fit waits for a valid {' and a '.join(missing)} night"
    return None


def needs_fit(store: Store) -> bool:
    """The valid nights differ from those of the newest fit."""
    last = store.last_fit()
    valid = [n.id for n in store.nights(valid=True)]
    return bool(valid) and (last is None or sorted(last[1]) != sorted(valid))


async def _step(cmd: list[str]) -> tuple[int, str]:
    proc = await asyncio.create_subprocess_exec(
        *cmd, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        _, err = await proc.communicate()
    except asyncio.CancelledError:  # the daemon stops: do not leave the fit running
        proc.kill()
        await proc.wait()
        raise
    lines = err.decode(errors="replace").strip().splitlines()
    return proc.returncode, lines[-1] if lines else ""


async def _steps(store: Store, steps: list[list[str]], what: str) -> bool:
    """Run the subprocesses in turn; False at the first that fails (logged, an event kept)."""
    for cmd in steps:
        code, last = await _step(cmd)
        if code != 0:
            _LOG.error("%s step %s failed (%d): %s", what, cmd[3], code, last)
            store.add_event("error", f"{what} failed at {cmd[3]}")
            return False
    return True


def fit_arguments(cfg: Config, nights_csv: Path, out_json: Path, model_dir: str) -> list[str]:
    """``impctl fit`` arguments of the daemon's fit: what the config tells it about the house
    (``[fit] night_gain_w`` and ``night_gain_sd_w``, a declared night gain [W]; not set: not
    declared, the fit measures, estimates or assumes it and says which; ``t_air_offset_sd_k``,
    ``t_out_offset_sd_k``, ``meter_error``, the instruments' declared uncertainty;
    ``emitter``, the declared emitter)."""
    args = ["fit", "--nights", str(nights_csv), "--json", str(out_json), "--model-dir",
            model_dir]
    if cfg.fit.night_gain_w is not None:
        args += ["--night-gain-w", repr(cfg.fit.night_gain_w)]
        if cfg.fit.night_gain_sd_w is not None:
            args += ["--night-gain-sd-w", repr(cfg.fit.night_gain_sd_w)]
    # what the installer knows of the instruments; absent: the fit assumes and says so
    for key in ("t_air_offset_sd_k", "t_out_offset_sd_k", "meter_error"):
        if getattr(cfg.fit, key) is not None:
            args += ["--" + key.replace("_", "-"), repr(getattr(cfg.fit, key))]
    return args + emitter_arguments(cfg)


def emitter_arguments(cfg: Config) -> list[str]:
    """``--emitter KIND`` when ``[fit] emitter`` declares it (``impctl fit`` and
    ``impctl season`` alike); nothing when not: the season model reads the heating water."""
    return ["--emitter", cfg.fit.emitter] if cfg.fit.emitter else []


async def run_fit(store: Store, cfg: Config) -> dict | None:
    """Export the valid nights and fit them; in adaptive mode predict the next night too.

    Returns the fit JSON (stored), or None when a step failed (logged, an event kept).
    """
    work = Path(cfg.state_dir) / "fit"
    work.mkdir(parents=True, exist_ok=True)
    nights_csv, out_json, next_json = work / "nights.csv", work / "fit.json", work / "next.json"
    ids = [n.id for n in store.nights(valid=True)]
    base = _base()
    model_dir = cfg.model_dir or str(Path(cfg.state_dir) / "models")
    steps = [
        # The IMP nights and the owner records: the fit runs the season model on them all.
        _export(base, cfg, nights_csv),
        [*base, *fit_arguments(cfg, nights_csv, out_json, model_dir)],
    ]
    if not await _steps(store, steps, "fit"):
        return None
    result = json.loads(out_json.read_text())
    fit_id = store.add_fit(ids, result)
    store.add_event("info", f"fit stored ({len(ids)} nights)")
    _LOG.info("fit stored for nights %s", ids)
    await _curve(cfg, base, nights_csv, out_json, work)
    if cfg.campaign.adaptive:
        await _predict(store, cfg, fit_id, base, out_json, nights_csv, next_json)
    return result


def _base() -> list[str]:
    # Niced: the fit (torch, a core for seconds to minutes) never slows tonight's sampling.
    return [sys.executable, "-c", f"import os; os.nice({FIT_NICE}); "
            "from impctl.cli import main; main()"]


def _export(base: list[str], cfg: Config, nights_csv: Path) -> list[str]:
    return [*base, "export", "--db", str(cfg.db_path), "--format", "csv", "--out",
            str(nights_csv), "--force"]


def season_refreshable(store: Store) -> tuple[int, dict] | None:
    """The newest fit's (id, result) when it holds a season model a morning refit can start
    from."""
    newest = store.newest_fit()
    if newest is None:
        return None
    theta = (newest[1].get("season") or {}).get("theta")
    return newest if isinstance(theta, dict) else None


async def refresh_season(store: Store, cfg: Config) -> dict | None:
    """The morning refit: the season model alone (``impctl season``, no torch), its search
    started where the newest fit's ended, on every recorded night; its result replaces that
    fit's season block. None when there is nothing to start from, a step failed (logged, an
    event kept) or a full fit stored a newer result meanwhile."""
    newest = season_refreshable(store)
    if newest is None:
        return None
    fit_id, last = newest
    work = Path(cfg.state_dir) / "fit"
    work.mkdir(parents=True, exist_ok=True)
    nights_csv, last_json, out_json = (work / "season_nights.csv", work / "season_from.json",
                                       work / "season.json")
    last_json.write_text(json.dumps(last))
    base = _base()
    steps = [_export(base, cfg, nights_csv),
             [*base, "season", "--nights", str(nights_csv), "--warm-start", str(last_json),
              "--json", str(out_json), "--tz", cfg.timezone, *emitter_arguments(cfg)]]
    if not await _steps(store, steps, "season refit"):
        return None
    block = json.loads(out_json.read_text())["season"]
    if not store.refresh_fit_season(fit_id, block):
        _LOG.info("season refit dropped: a newer fit was stored meanwhile")
        return None
    text = (f"season model refreshed: {block['owner_nights']} owner nights, HLC "
            f"{_value(block, 'hlc_w_per_k')} W/K")
    store.add_event("info", text)
    _LOG.info("%s (search %.2f s from the last fit's)", text, block["search"]["time_s"])
    return block


def _value(block: dict, key: str) -> str:
    v = (block.get(key) or {}).get("value")
    return "—" if v is None else f"{v:.0f}"


async def _curve(cfg: Config, base: list[str], nights_csv: Path, fit_json: Path,
                 work: Path) -> None:
    """``impctl curve`` on the exported nights and the new fit, kept as
    ``<state_dir>/curve.json``. Never fatal: nights without flow and return temperatures give
    no curve (one line in the log), and the last kept one stays."""
    out = work / "curve.json"
    out.unlink(missing_ok=True)
    code, last = await _step([*base, "curve", "--nights", str(nights_csv), "--fit",
                              str(fit_json), "--json", str(out), "--tz", cfg.timezone,
                              "--margin-k", repr(cfg.curve.margin_k)])
    if code != 0 or not out.exists():
        _LOG.info("no heating curve from these nights: %s", last or f"exit {code}")
        return
    keep_curve(cfg.state_dir, out)
    _LOG.info("heating curve kept (%s)", Path(cfg.state_dir) / "curve.json")


async def _predict(store: Store, cfg: Config, fit_id: int, base: list[str], fit_json: Path,
                   nights_csv: Path, next_json: Path) -> None:
    """``impctl campaign next`` from the new fit; its candidates are stored with the fit.
    Without them the policy follows its default order: logged, never fatal."""
    fc = forecast(store, cfg)
    if fc.t_out_c is None:
        _LOG.warning("no outdoor reading: no prediction for the next night")
        return
    camp = cfg.campaign
    start, end = cfg.window_minutes
    window_h = ((end - start) % (24 * 60)) / 60
    cmd = [*base, "campaign", "next", "--fit", str(fit_json), "--nights", str(nights_csv),
           "--forecast-t-out-c", f"{fc.t_out_c:g}",
           "--constrained-setpoint-c", f"{camp.constrained_setpoint_c:g}",
           "--normal-setpoints-c", ",".join(f"{sp:g}" for sp in camp.normal_setpoints_c),
           "--comfort-band-k", f"{cfg.night.comfort_band_k:g}",
           "--preheat-h", f"{cfg.night.preheat_h:g}", "--window-h", f"{window_h:g}",
           "--tz", cfg.timezone, "--json", str(next_json)]
    code, last = await _step(cmd)
    if code != 0:
        _LOG.error("campaign next failed (%d): %s; the next night follows the default order",
                   code, last)
        store.add_event("error", "campaign next failed")
        return
    block = json.loads(next_json.read_text())
    block["forecast_source"] = fc.source
    store.set_fit_candidates(fit_id, block)
    _LOG.info("predictions for the next night stored (forecast T_out %.1f °C, %s)",
              fc.t_out_c, fc.source)
