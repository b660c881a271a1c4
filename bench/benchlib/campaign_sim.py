"""The nights ``bench/campaign.py`` replays, simulated once for every household: each variant
(the constrained night, a normal night at each setpoint) after a night of its own kind, and —
since h18h — after the other kind (alternating schedules), so that a campaign replays the
night simulated after the night it ran the date before.
"""

from __future__ import annotations

import sys

import numpy as np

from impctl.population.households import sample_households
from impctl.population.imp_run.synth import run_schedule, run_schedule_plant, sample_nights
from impctl.population.realism import sample_params

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from benchlib.campaign_nights import (  # noqa: E402
    alternating_schedule,
    night_sources,
    variant_schedule,
    variants,
)
from benchlib.fit_protocol import short_constrained  # noqa: E402  (h14w: the gateway's validity rule)

VARIANTS = variants()   # (kind, setpoint °C): the constrained night first, then each normal
CONSTRAINED_C = VARIANTS[0][1]
#: what each replayed night was simulated after: (variant, previous variant or None)
SOURCES = night_sources()


def simulate_variants(n: int, k: int, plant: str, step_s: float, progress, seed: int,
                      gateway_stop: bool = True, after_same: bool = False):
    """nights[s][i][j], forecast[i][j] [°C], first outdoor reading[s][i][j] [°C],
    short[s][i][j] (a constrained night the gateway counts invalid: < MIN_NIGHT_H after the
    1 h lag), s indexing :data:`SOURCES` (the households and weather of population ``seed``):
    night j of household i of each variant, after a night of its own kind (one schedule per
    variant), and — unless ``after_same`` (the replay before h18h) — a constrained night after
    a normal night at each setpoint and a normal night after a constrained one (two alternating
    schedules per normal setpoint, one for each parity of the dates: every date has both).

    ``gateway_stop``: the constrained nights end as the gateway ends them (at T_min or its
    anticipated end, not switched off after a short pre-heat; issue 14, h14w's
    ``stop_at_t_min``) and are cut there; else they cool to the window's end (before h18f)."""
    houses = sample_households(n, seed=seed)
    params = sample_params(n, seed) if plant == "realistic" else None
    forecast = None

    def simulate(sched, label: str):
        """Per date j: nights[i][j], first T_out [i, j] °C, short [i, j]."""
        nonlocal forecast
        kinds = [kind for _, kind, _, _, _ in sched.windows]
        stop = gateway_stop and "constrained" in kinds
        if plant == "realistic":
            sim, spc = run_schedule_plant(houses, sched, params, seed=seed, stop_at_t_min=stop)
            t_out, noise = sim.t_out_c, 0.0
        else:
            sim, spc = run_schedule(houses, sched, stop_at_t_min=stop)
            t_out, noise = sched.t_out_c, 0.05
        dates_short = np.zeros((n, k), bool)
        c_dates = [j for j, kind in enumerate(kinds) if kind == "constrained"]
        if c_dates:
            dates_short[:, c_dates] = short_constrained(spc, sched).T
        per_day = int(round(86400 / sched.dt_s))
        if forecast is None:   # persistence: last night's mean outdoor temperature
            forecast = np.array([[float(np.mean(t_out[w0 - per_day:w1 - per_day, i]))
                                  for _, _, w0, w1, _ in sched.windows] for i in range(n)])
        first = np.array([[float(t_out[w0, i]) for _, _, w0, _, _ in sched.windows]
                          for i in range(n)])
        nights = [sample_nights(sim, spc, sched, i, sample_step_s=step_s, quantise_k=0.1,
                                power_noise=noise, seed=seed + i) for i in range(n)]
        progress(f"simulated {label} for {n} households"
                 + (f" ({int(dates_short.sum())} of {n * len(c_dates)} constrained nights "
                    f"short)" if c_dates else ""), force=True)
        return nights, first, dates_short

    base = [simulate(variant_schedule(n, k, kind, sp, seed), f"variant {kind} {sp:g} °C")
            for kind, sp in VARIANTS]
    alternating = {}   # (normal variant, parity of the constrained dates) → simulated
    if not after_same:
        for p in range(1, len(VARIANTS)):
            for parity in (0, 1):
                alternating[p, parity] = simulate(
                    alternating_schedule(n, k, CONSTRAINED_C, VARIANTS[p][1], parity, seed),
                    f"c{CONSTRAINED_C:g} / n{VARIANTS[p][1]:g} alternating, constrained on "
                    f"{'even' if parity == 0 else 'odd'} dates")
    nights, first_t_out, short = [], [], []
    for v, prev in SOURCES:
        if prev is None:
            parts = [base[v]] * k
        elif v == 0:   # constrained on date j after normal prev: the schedule with c on j
            parts = [alternating.get((prev, j % 2), base[v]) for j in range(k)]
        else:          # normal v on date j after constrained: the schedule with n on j
            parts = [alternating.get((v, 1 - j % 2), base[v]) for j in range(k)]
        nights.append([[parts[j][0][i][j] for j in range(k)] for i in range(n)])
        first_t_out.append(np.array([[parts[j][1][i, j] for j in range(k)] for i in range(n)]))
        short.append(np.array([[parts[j][2][i, j] for j in range(k)] for i in range(n)]))
    return houses, nights, forecast, first_t_out, short
