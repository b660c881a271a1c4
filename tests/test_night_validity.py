"""A constrained night the gateway calls valid is one the fit uses: the gateway measures its
usable hours as the fit does (the complete samples from the first one + the emission lag, up
to where the heating resumed). Real SQLite store, the fit's own night preparation."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from impctl.controller import NightPolicy
from impctl.controller.assess import assess_night
from impctl.fit.nights.data import prepare_nights
from impctl.imp import NightSamples
from impctl.store import Sample, Store

START = datetime(2026, 1, 12, 21, tzinfo=UTC)


def _judge(tmp_path, minutes: list[float], q_of=lambda m: 0.0, missing=(), ended=None):
    """(gateway valid, its reasons, fit keeps the night) for one constrained night sampled at
    ``minutes`` after the window's start, ended at ``ended`` [min] (default its last sample)."""
    with Store(tmp_path / "impctl.sqlite") as store:
        nid = store.create_night("constrained", 21.0, START, START + timedelta(hours=7))
        for m in minutes:
            ts = START + timedelta(minutes=m)
            t_air = None if m in missing else 23.0 - 0.01 * m
            store.add_sample(Sample(nid, ts, t_air_c=t_air, t_out_c=-3.0, q_hc_w=q_of(m),
                                    p_el_w=q_of(m) / 3.0, working_function=0, defrost=False,
                                    error_bits=0, loop_mode=0, setpoint_c=21.0,
                                    dhw_active=False))
        end = minutes[-1] if ended is None else ended
        store.set_night_state(nid, "done", ended=START + timedelta(minutes=end))
        valid, reasons = assess_night(store, nid, NightPolicy(sample_interval_s=300))
        samples = [s for s in store.samples(nid) if s.t_air_c is not None]
    t0 = samples[0].ts
    night = NightSamples(
        night_id="n", kind="constrained", start=t0,
        time_s=np.array([(s.ts - t0).total_seconds() for s in samples]),
        t_air_c=np.array([s.t_air_c for s in samples]), t_out_c=np.full(len(samples), -3.0),
        q_hc_w=np.array([s.q_hc_w for s in samples]), setpoint_c=21.0)
    kept, _, _ = prepare_nights([night])
    return valid, reasons, bool(kept)


@pytest.mark.parametrize(("minutes", "q_of", "missing", "ended", "fit_keeps"), [
    # ended 4 h 04 min after the start, but sampled every 7 min: the samples after the lag
    # span 63 … 238 min, 2 h 55 min (the window's length minus the lag said 3 h 04 min)
    (list(np.arange(0, 245, 7.0)), lambda m: 0.0, (), 244.0, False),
    # sampled every 5 min to the end: 60 … 245 min, 3 h 05 min
    (list(np.arange(0, 250, 5.0)), lambda m: 0.0, (), None, True),
    # 5 h of night, but the heating resumed at 3 h 50 min: 2 h 45 min of cooling
    (list(np.arange(0, 301, 5.0)), lambda m: 1500.0 if m >= 230 else 0.0, (), None, False),
    # 5 h of night, T_air missing from 3 h 55 min on (the fit drops incomplete rows)
    (list(np.arange(0, 301, 5.0)), lambda m: 0.0, set(np.arange(235, 301, 5.0)), None, False),
])
def test_the_gateway_and_the_fit_agree_on_usable_hours(tmp_path, minutes, q_of, missing,
                                                       ended, fit_keeps):
    valid, reasons, kept = _judge(tmp_path, minutes, q_of, missing, ended)
    assert kept is fit_keeps
    short = any("h of data after the emission lag" in r for r in reasons)
    assert short is (not fit_keeps), reasons


def _stored_night(store: Store, minutes, missing=()) -> int:
    """One constrained night, cooling from 23 °C, ended at its last sample; assessed."""
    from impctl.controller.assess import record_end
    from impctl.controller.plan import NightRequest

    nid = store.create_night("constrained", 21.0, START, START + timedelta(hours=7))
    for m in minutes:
        store.add_sample(Sample(nid, START + timedelta(minutes=m),
                                t_air_c=None if m in missing else 23.0 - 0.01 * m,
                                t_out_c=-3.0, q_hc_w=0.0, p_el_w=0.0, working_function=0,
                                defrost=False, error_bits=0, loop_mode=0, setpoint_c=21.0,
                                dhw_active=False))
    req = NightRequest("constrained", 21.0, START, START + timedelta(hours=7))
    record_end(store, NightPolicy(sample_interval_s=300), nid, req, "done",
               ["reached T_min 20.0 °C"], START + timedelta(minutes=minutes[-1]))
    return nid


def test_a_night_too_short_for_the_fit_and_right_otherwise_is_the_season_models(tmp_path):
    """Reached T_min after 100 min: too short for the IMP fit, not valid — yet its cooling is
    exported, labelled, read as a constrained night and left out of the IMP fit; a short night
    with a sensor missing too is not exported at all."""
    from impctl.imp.files.nights_csv import read_nights
    from impctl.imp.night import SHORT_NOTE, split_owner
    from impctl.imp.protocol import SHORT_NIGHT
    from impctl.store.export import export_nights

    minutes = list(np.arange(0, 101, 5.0))
    with Store(tmp_path / "impctl.sqlite") as store:
        short = _stored_night(store, minutes)
        blind = _stored_night(store, minutes, missing=set(minutes[5:10]))
        nights = {x.id: x for x in store.nights()}
        n = export_nights(store, tmp_path / "nights.csv", "csv")
    assert not nights[short].valid and SHORT_NIGHT in nights[short].reasons, nights[short]
    assert not nights[blind].valid and SHORT_NIGHT not in nights[blind].reasons
    assert n == len(minutes)
    [read] = read_nights(tmp_path / "nights.csv", "UTC")
    assert (read.kind, read.label, len(read.time_s)) == ("constrained", SHORT_NIGHT, n)
    imp, note = split_owner([read])
    assert imp == [] and note == f"{SHORT_NOTE} (1)"


def test_a_night_ended_at_t_min_is_covered_up_to_its_end(tmp_path):
    """Through the gateway's own end of night (record_end): 4½ h of cooling to T_min is a
    valid night — its coverage counts up to where it ended, not to the window's end (it was
    judged before its end was stored, and every night ended early was called not valid)."""
    with Store(tmp_path / "impctl.sqlite") as store:
        nid = _stored_night(store, list(np.arange(0, 271, 5.0)))
        night = store.night(nid)
    assert night.valid and night.reasons == ("reached T_min 20.0 °C",), night
