"""Issue 15: every night's Q_HC is cross-checked; a night that fails is stored, invalid, with
the reason. Real SQLite store; samples as the controller writes them."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from impctl.controller import NightPolicy
from impctl.controller.assess import assess_night
from impctl.store import Sample, Store

START = datetime(2026, 1, 12, 22, tzinfo=UTC)


def _night(tmp_path, q_of, p_of=lambda i: 1000.0 + 5 * (i % 7)) -> tuple[bool, list[str]]:
    with Store(tmp_path / "impctl.sqlite") as store:
        nid = store.create_night("normal", 21.0, START, START + timedelta(hours=7))
        for i in range(7 * 20 + 1):  # one sample every 3 min
            store.add_sample(Sample(nid, START + timedelta(minutes=3 * i), t_air_c=21.0,
                                    t_out_c=-3.0, q_hc_w=q_of(i), p_el_w=p_of(i),
                                    t_supply_c=35.0 + (i % 5) * 0.5, t_return_c=30.0,
                                    working_function=0, defrost=False, error_bits=0,
                                    loop_mode=1, setpoint_c=21.0, dhw_active=False))
        store.set_night_state(nid, "done", ended=START + timedelta(hours=7))
        valid, reasons = assess_night(store, nid, NightPolicy(sample_interval_s=180))
        store.assess_night(nid, valid, reasons)
        stored = store.night(nid)
        assert stored.valid is valid and list(stored.reasons) == reasons
        return valid, reasons


def test_a_believable_night_passes(tmp_path):
    valid, reasons = _night(tmp_path, lambda i: 3200.0 + 17 * (i % 11))
    assert valid and reasons == []


@pytest.mark.parametrize(("q_of", "p_of", "expected"), [
    # a TT3000 answering the undocumented 2329 with 1234 W while P_el reads 0
    (lambda i: 1234.0, lambda i: 0.0, "disagrees with electrical power"),
    # a COP of 20: the scale of Q_HC (or of P_el) is wrong
    (lambda i: 20000.0 + i, lambda i: 1000.0 + i, "disagrees with electrical power"),
    # stuck register while the compressor modulates
    (lambda i: 4088.0, lambda i: 600.0 + 40 * (i % 20), "stuck at 4088 W"),
    # far beyond any residential heat pump
    (lambda i: 60000.0, lambda i: 9000.0 + i, "outside 0…25000 W"),
])
def test_an_implausible_heat_output_makes_the_night_invalid(tmp_path, q_of, p_of, expected):
    valid, reasons = _night(tmp_path, q_of, p_of)
    assert not valid and any(expected in r for r in reasons), reasons
