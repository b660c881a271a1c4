"""The virtual clock (shared across processes) and the persistent write budget."""

from __future__ import annotations

import logging
import sqlite3
import subprocess
import sys
from datetime import UTC, date, datetime, timedelta

import pytest

from impctl.clock import VirtualClock
from impctl.errors import InputError
from impctl.heatpump import WriteBudget, WriteBudgetExceeded

EPOCH = datetime(2026, 1, 12, 20, tzinfo=UTC)


class FakeWall:
    """A wall clock the test moves by hand [POSIX s]."""

    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def test_sim_time_is_epoch_plus_scaled_wall_time():
    wall = FakeWall(1_000_000.0)
    clock = VirtualClock(EPOCH, 600.0, 1_000_000.0, wall=wall)
    assert clock.now() == EPOCH
    wall.now += 10.0
    assert clock.now() == EPOCH + timedelta(minutes=100)
    assert clock.wall_seconds(60.0) == pytest.approx(0.1)
    assert clock.sim_seconds(1.0) == 600.0


def test_same_spec_gives_same_time_in_another_clock():
    wall = FakeWall(1_700_000_123.25)
    first = VirtualClock(EPOCH, 3600.0, wall=wall)
    second = VirtualClock.from_spec(first.spec(), wall=wall)
    for step in (0.0, 0.5, 123.0):
        wall.now += step
        assert second.now_s() == first.now_s()


def test_spec_reproduces_time_in_another_process():
    clock = VirtualClock(EPOCH, 600.0, 1_700_000_000.0)
    code = ("import sys; from impctl.clock import VirtualClock; "
            "c = VirtualClock.from_spec(sys.argv[1], wall=lambda: 1700000100.0); "
            "print(repr(c.now_s()))")
    out = subprocess.run([sys.executable, "-c", code, clock.spec()], capture_output=True,
                         text=True, check=True).stdout
    assert float(out) == EPOCH.timestamp() + 100.0 * 600.0


def test_real_clock_follows_wall_time():
    wall = FakeWall(1_800_000_000.0)
    clock = VirtualClock(None, 1.0, 0.0, wall=wall)
    assert clock.now_s() == 1_800_000_000.0
    real = VirtualClock.real()
    assert abs(real.now() - datetime.now(UTC)) < timedelta(seconds=5)


@pytest.mark.parametrize("spec", ["epoch=yesterday,factor=1,wall_epoch=0", "factor=2",
                                  "epoch=2026-01-01T00:00+00:00,speed=2",
                                  "epoch=2026-01-01T00:00+00:00,factor=0,wall_epoch=1"])
def test_bad_clock_spec(spec):
    with pytest.raises(InputError):
        VirtualClock.from_spec(spec)


def test_clock_needs_zone_and_positive_factor():
    with pytest.raises(InputError, match="time zone"):
        VirtualClock(datetime(2026, 1, 1), 1.0)
    with pytest.raises(InputError, match="factor"):
        VirtualClock(EPOCH, -1.0)


def test_budget_refuses_loudly_past_the_daily_limit(tmp_path, caplog):
    day = date(2026, 1, 12)
    with WriteBudget(tmp_path / "w.sqlite", 3) as budget:
        assert [budget.consume(2187, day) for _ in range(3)] == [1, 2, 3]
        with caplog.at_level(logging.ERROR), pytest.raises(WriteBudgetExceeded,
                                                            match="2187.*3 of 3"):
            budget.consume(2187, day)
        assert "write budget exhausted for register 2187" in caplog.text
        assert budget.used(2187, day) == 3  # the refused attempt is not counted
        assert budget.remaining(2187, day) == 0
        assert budget.consume(2042, day) == 1  # per register
        assert budget.consume(2187, day + timedelta(days=1)) == 1  # a new day


def test_budget_persists_and_is_shared(tmp_path):
    path = tmp_path / "state" / "w.sqlite"
    day = date(2026, 1, 12)
    with WriteBudget(path, 2) as first:
        first.consume(2187, day)
    with WriteBudget(path, 2) as again, WriteBudget(path, 2) as other:
        assert again.used(2187, day) == 1 and again.lifetime(2187) == 1
        other.consume(2187, day)  # e.g. a restore watchdog in another process
        with pytest.raises(WriteBudgetExceeded):
            again.consume(2187, day)
        assert again.lifetime(2187) == 2
    mode = sqlite3.connect(path).execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"


def test_budget_per_register_override_and_validation(tmp_path):
    with WriteBudget(tmp_path / "w.sqlite", 5, {2042: 1}) as budget:
        day = date(2026, 1, 12)
        budget.consume(2042, day)
        with pytest.raises(WriteBudgetExceeded):
            budget.consume(2042, day)
        assert budget.limit(2187) == 5
    with pytest.raises(InputError):
        WriteBudget(tmp_path / "x.sqlite", -1)
