"""The store's campaign tables: the fixed plan, the fits with their night counts and
predictions, and the adaptive campaign's decisions (a mixin of :class:`~impctl.store.Store`)."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Sequence
from datetime import datetime

from ._times import _dt, _iso, _now
from .records import CampaignDecision, FitRecord


class CampaignTables:
    """Queries on ``campaign``, ``fits`` and ``decisions`` (``self._db``: the connection)."""

    _db: sqlite3.Connection

    # -- campaign plan ---------------------------------------------------------------------
    def set_campaign(self, plan: Sequence[tuple[str, float]]) -> None:
        """Replace the campaign plan (kind, setpoint °C) keeping links of entries that match."""
        self._db.execute("BEGIN IMMEDIATE")
        try:
            old = {r["seq"]: r for r in self._db.execute("SELECT * FROM campaign")}
            self._db.execute("DELETE FROM campaign")
            for seq, (kind, sp) in enumerate(plan):
                keep = old.get(seq)
                link = keep["night_id"] if keep and (keep["kind"], keep["setpoint_c"]) == (
                    kind, sp) else None
                self._db.execute("INSERT INTO campaign VALUES (?, ?, ?, ?)",
                                 (seq, kind, sp, link))
            self._db.execute("COMMIT")
        except BaseException:
            self._db.execute("ROLLBACK")
            raise

    def campaign(self) -> list[tuple[int, str, float, int | None, bool | None]]:
        """The plan: (seq, kind, setpoint °C, linked night id, that night's validity)."""
        rows = self._db.execute(
            "SELECT c.seq, c.kind, c.setpoint_c, c.night_id, n.valid FROM campaign c"
            " LEFT JOIN nights n ON n.id = c.night_id ORDER BY c.seq")
        return [(r[0], r[1], r[2], r[3], None if r[4] is None else bool(r[4])) for r in rows]

    def link_campaign(self, seq: int, night_id: int) -> None:
        """Attach a night to a plan entry (replacing an earlier, invalid attempt)."""
        self._db.execute("UPDATE campaign SET night_id = ? WHERE seq = ?", (night_id, seq))

    # -- fits and events -------------------------------------------------------------------
    def add_fit(self, night_ids: Sequence[int], result: dict) -> int:
        """Store a fit result (JSON-serialisable dict) with its night count; returns its id."""
        cur = self._db.execute(
            "INSERT INTO fits (created, nights, result, night_count) VALUES (?, ?, ?, ?)",
            (_iso(_now()), json.dumps(list(night_ids)), json.dumps(result), len(night_ids)))
        return int(cur.lastrowid)

    def set_fit_candidates(self, fit_id: int, block: dict) -> None:
        """Attach the predictions of ``impctl campaign next`` (its JSON) to a fit."""
        self._db.execute("UPDATE fits SET candidates = ? WHERE id = ?",
                         (json.dumps(block), fit_id))

    def fits(self) -> list[FitRecord]:
        """Every fit, oldest first: how the intervals shrank night after night."""
        return [_fit(r) for r in self._db.execute("SELECT * FROM fits ORDER BY id")]

    def night_t_out_means(self) -> dict[int, float]:
        """Mean outdoor temperature [°C] of each night's samples (nights without any: absent)."""
        rows = self._db.execute("SELECT night_id, AVG(t_out_c) FROM samples"
                                " WHERE t_out_c IS NOT NULL GROUP BY night_id")
        return {int(r[0]): float(r[1]) for r in rows}

    def add_decision(self, action: str, reason: str, *, kind: str | None = None,
                     setpoint_c: float | None = None, reached: bool = False,
                     act: datetime | None = None, forecast_t_out_c: float | None = None,
                     forecast_source: str | None = None) -> int:
        """Keep the adaptive campaign's decision for one night (``run``/``skip``/``stop``).

        ``act``: the (daemon clock) instant the night's preheat would start.
        """
        cur = self._db.execute(
            "INSERT INTO decisions (created, act, action, kind, setpoint_c, reason, reached,"
            " forecast_t_out_c, forecast_source) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (_iso(_now()), _iso(act), action, kind, setpoint_c, reason, int(reached),
             forecast_t_out_c, forecast_source))
        return int(cur.lastrowid)

    def decisions(self, limit: int = 50) -> list[CampaignDecision]:
        """The newest decisions first."""
        rows = self._db.execute("SELECT * FROM decisions ORDER BY id DESC LIMIT ?", (limit,))
        return [CampaignDecision(
            id=r["id"], created=_dt(r["created"]), act=_dt(r["act"]), action=r["action"],
            kind=r["kind"], setpoint_c=r["setpoint_c"], reason=r["reason"],
            reached=bool(r["reached"]), forecast_t_out_c=r["forecast_t_out_c"],
            forecast_source=r["forecast_source"]) for r in rows]

    def newest_fit(self) -> tuple[int, dict] | None:
        """The newest fit's (id, result), or None."""
        row = self._db.execute("SELECT id, result FROM fits ORDER BY id DESC LIMIT 1").fetchone()
        return None if row is None else (int(row[0]), json.loads(row[1]))

    def refresh_fit_season(self, fit_id: int, season: dict) -> bool:
        """Put a newer season model into fit ``fit_id``'s result, when that fit is still the
        newest (else a full fit has stored a newer one meanwhile, which read every night
        itself): the IMP fit's fields are left as they were. True when stored."""
        with self._immediate():
            newest = self.newest_fit()
            if newest is None or newest[0] != fit_id:
                return False
            result = newest[1]
            result["season"] = season
            self._db.execute("UPDATE fits SET result = ? WHERE id = ?",
                             (json.dumps(result), fit_id))
        return True

    def last_fit(self) -> tuple[datetime, list[int], dict] | None:
        """The newest fit: (created, night ids, result), or None."""
        row = self._db.execute("SELECT * FROM fits ORDER BY id DESC LIMIT 1").fetchone()
        if row is None:
            return None
        return _dt(row["created"]), json.loads(row["nights"]), json.loads(row["result"])


def _fit(row: sqlite3.Row) -> FitRecord:
    nights = json.loads(row["nights"])
    count = row["night_count"]
    return FitRecord(id=row["id"], created=_dt(row["created"]), nights=nights,
                     night_count=len(nights) if count is None else int(count),
                     result=json.loads(row["result"]),
                     candidates=None if row["candidates"] is None else json.loads(
                         row["candidates"]))
