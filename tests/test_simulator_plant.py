"""impctl-sim on the realistic plant: what a real Kronoterm shows, over real Modbus TCP.

Compressor and pumps cycle, supply and return split and close with the compressor, thermal and
electrical power follow it, the room register shows the room *sensor* (lag, resolution), DHW
and defrost come from the plant; ``--plant iso`` keeps the ideal plant; bad ``[plant.*]``
tables in the house file are one line and exit status 2.
"""

from __future__ import annotations

import asyncio

import pytest
from impctl_sim import PlantParams, SimConfig, constant_weather
from impctl_sim.cli import main as sim_main
from impctl_sim.config import default_realism
from sim_fixtures import client, clock, run, simulator

from impctl.model import default_house

REGISTERS = ("compressor_bits", "main_pump", "loop1_pump", "t_supply", "t_return",
             "power_thermal", "power_electrical", "room_loop1", "working_function", "defrost")


async def _poll(hp, sim, hours: float, every_s: float = 120.0) -> list[dict]:
    """Read the registers every ``every_s`` simulated seconds for ``hours``."""
    rows, end = [], sim.plant.time_s + hours * 3600
    while sim.plant.time_s < end:
        sim.faults.freeze = True  # one consistent register image while we read it
        try:
            row = {name: (await hp.read(name)).value for name in REGISTERS}
        finally:
            sim.faults.freeze = False
        row["compressor_bits"] = int(row["compressor_bits"])
        rows.append(row)
        await asyncio.sleep(every_s / sim.clock.factor)
    return rows


def test_compressor_pumps_and_powers_cycle_together():
    # An on/off unit with a room thermostat and a coarse, lagging room sensor on a mild night.
    realism = default_realism().with_section("heat_pump", min_modulation=1.0, control=1)
    realism = realism.with_section("sensors", t_air_quantum_k=0.5, t_air_lag_s=600.0)

    async def body():
        cfg = SimConfig(clock=clock(3600.0), weather=constant_weather(5.0), realism=realism)
        async with simulator(cfg) as sim, client(sim) as hp:
            rows = await _poll(hp, sim, hours=6.0)
            assert sim.plant.kind == "realistic"
            return rows, sim.plant.realism.heat_pump.standby_w

    rows, standby_w = run(body(), timeout_s=60)
    on = [r for r in rows if r["compressor_bits"] & 1]
    off = [r for r in rows if not r["compressor_bits"] & 1]
    starts = sum(1 for a, b in zip(rows, rows[1:], strict=False)
                 if not a["compressor_bits"] & 1 and b["compressor_bits"] & 1)
    assert starts >= 2 and len(on) >= 5 and len(off) >= 5  # it cycles
    for r in on:  # running: heat flows, supply above return, the pumps run
        assert r["power_thermal"] > 0 and r["power_electrical"] > standby_w
        assert r["t_supply"] > r["t_return"] and r["main_pump"] == 1
        assert r["working_function"] == 0
    for r in off:  # stopped: no heat, standby power, supply = return, loop pump still on
        assert r["power_thermal"] == 0 and r["power_electrical"] == pytest.approx(standby_w, 1)
        assert abs(r["t_supply"] - r["t_return"]) <= 0.11 and r["loop1_pump"] == 1
        assert r["working_function"] == 5
    # The room register is the sensor: 0.5 K steps.
    assert {round(r["room_loop1"] * 10) % 5 for r in rows} == {0}
    assert len({r["room_loop1"] for r in rows}) >= 2


def test_dhw_and_defrost_come_from_the_plant():
    realism = default_realism().with_section("heat_pump", defrost=1)

    async def body():
        cfg = SimConfig(clock=clock(3600.0), weather=constant_weather(0.0), realism=realism,
                        plant=PlantParams(dhw_period_s=4 * 3600.0, dhw_duration_s=1800.0))
        async with simulator(cfg) as sim, client(sim) as hp:
            return await _poll(hp, sim, hours=5.0, every_s=60.0)

    rows = run(body(), timeout_s=60)
    dhw = [r for r in rows if r["working_function"] == 1]
    defrost = [r for r in rows if r["defrost"]]
    assert dhw and defrost
    assert all(r["power_thermal"] > 0 and r["compressor_bits"] & 1 for r in dhw)
    # The heat meter integrates positive heat only: a defrost reads no heat.
    assert all(r["power_thermal"] == 0 and r["compressor_bits"] & 1 for r in defrost)


def test_iso_plant_is_still_there():
    async def body():
        cfg = SimConfig(clock=clock(1.0), plant_kind="iso")
        async with simulator(cfg) as sim, client(sim) as hp:
            snap = await hp.snapshot()
            return sim.plant.kind, snap.t_air_c.value, sim.plant.t_air_c

    kind, seen, true = run(body())
    assert kind == "iso" and seen == pytest.approx(round(true, 1))


def test_house_file_plant_tables_and_bad_values(tmp_path, capsys):
    from impctl_sim.cli import _house_and_realism

    base = tmp_path / "base.toml"
    base.write_text("".join(f"{k} = {float(v)!r}\n" for k, v in default_house().as_dict().items()
                            if k != "max_heating_power"))
    good = tmp_path / "ufh.toml"
    good.write_text(base.read_text() + "[plant.emitter]\nkind = \"underfloor\"\n"
                    "[plant.heat_pump]\ncontrol = \"thermostat\"\n")
    _, realism = _house_and_realism(good, None, None)
    assert (realism.emitter.kind, realism.heat_pump.control) == (1, 1)
    assert realism.heat_pump.defrost == 0  # the simulator's default unless the file says so
    _, realism = _house_and_realism(good, "radiators", "curve")  # the flags win
    assert (realism.emitter.kind, realism.heat_pump.control) == (0, 0)
    bad = tmp_path / "bad.toml"
    bad.write_text(base.read_text() + "[plant.sensors]\nt_air_lag_s = 99999\n")
    with pytest.raises(SystemExit) as info:
        sim_main(["--house", str(bad), "--port", "0"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1
    assert "bad.toml" in err and "plant.sensors.t_air_lag_s" in err


@pytest.mark.parametrize("epoch", ["2026-01-12T21:15:00+01:00", "2026-03-29T03:30:00+02:00",
                                   "2026-10-25T01:00:00+00:00"])
def test_the_default_weather_starts_at_midnight_five_days_before_the_clock(epoch):
    """The simulator's own weather (built without pandas) is the generator's series from the
    midnight, in the clock's zone, five days before the clock's start, to the bit."""
    from datetime import datetime
    from zoneinfo import ZoneInfo

    import numpy as np
    import pandas as pd
    from impctl_sim import WeatherFeed

    from impctl.clock import VirtualClock
    from impctl.weather import winter_weather

    start = datetime.fromisoformat(epoch).astimezone(ZoneInfo("Europe/Ljubljana"))
    c = VirtualClock(epoch=start, factor=60.0)
    feed = SimConfig(weather_seed=4).weather_feed(c)
    series = winter_weather(pd.Timestamp(c.epoch).floor("D") - pd.Timedelta(days=5), days=62,
                            step_s=900, seed=4)
    expected = WeatherFeed(series)
    times = start.timestamp() + np.linspace(-4 * 86400.0, 70 * 86400.0, 97)
    assert [feed.t_out_c(t) for t in times] == [expected.t_out_c(t) for t in times]
