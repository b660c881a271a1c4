"""Does impctl's heating curve save electricity on realistic houses, and keep them warm?

Run:  .venv/bin/python bench/curve.py [--households 200] [--learn-days 21] [--winter-days 75]
          [--dt 60] [--margin-k 1.0] [--model-dir DIR] [--cache DIR] [--refit]
          [--plant SECTION.FIELD=VALUE ...] [--constant-flow] [--no-watch] [--oracle]

Per household of the validation population (``bench/fit.py``: seed 20260, the realistic plant
with its realism drawn by ``impctl.population.realism.sample_params``):

1. **the fit**: its IMP campaign as the gateway runs it (2 constrained nights kept, 6 normal
   nights; ``bench/benchlib/fit_protocol.py``), fitted as ``impctl fit`` fits them (the
   classifiers of ``--model-dir``): its fit JSON — :func:`fit_json`, the one place the fit is
   called;
2. **the owner's nights**: ``--learn-days`` days of the owner's winter (setpoint 21 °C day and
   night, the installer's curve: the plant's own, ``curve_gain``; with ``--constant-flow`` one
   flow temperature whatever the weather), recorded as a gateway
   records them (5-minute rows: room and outdoor sensors, the heat meter, flow, return, the
   curve's flow target, the electricity);
3. **impctl curve** on those rows and the fit JSON (``--margin-k``): the recommended curve.
   Where it is lower than the running curve (``lowers``) and within the 20–55 °C impctl
   writes, the household gets it, as two points at −15 and +15 °C (a Kronoterm's 2309/2314:
   a straight line); otherwise it keeps the installer's;
4. **the winter**: ``--winter-days`` days of another winter (other weather seeds), simulated
   twice from the same start — with the installer's curve and with impctl's — at ``--dt``
   seconds: electricity (the plant's ``electric_w``), space-heating COP (heat / electricity),
   hours with the true room below 21 − 0.5 °C, the coldest room, the coldest night against
   T_min = 21 − 2.5 °C.

Reported: medians of the paired differences with 95 % bootstrap intervals (households
resampled), over all households and by emitter and control; the share of households whose
curve changed; and the recommended curve's accuracy: the flow at 0 °C impctl's central need
puts against the flow the true house needs there (its true heat loss less its realised mean
night gain, through its true emitter), and the recommended curve (bound + margin) against it.

The simulation is day by day (memory stays flat over months); the fits and each household's
analysis are cached in ``--cache`` (``--refit`` redoes the fits).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from benchlib.curve_sim import (  # noqa: E402
    SETPOINT_C,
    T_MIN_C,
    Watch,
    installer_flow_c,
    simulate,
    true_flow_c,
)
from benchlib.fit_protocol import VAL_SEED, gateway_campaign, simulate_schedule, val_schedule  # noqa: E402,I001

from impctl.curve import analyse  # noqa: E402
from impctl.curve.data.rows import rows_from_table  # noqa: E402
from impctl.curve.need import FLOW_LIMITS_C, POINTS_T_OUT_C, writable  # noqa: E402
from impctl.errors import InputError  # noqa: E402
from impctl.plant import PlantCore  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402

LEARN_SEED, WINTER_SEED = 41001, 41002
BOOT = 2000


def fit_json(nights, model_dir) -> dict | None:
    """The household's fit JSON as ``impctl fit`` writes it (None when the fit refuses)."""
    from impctl.fit.estimator import NightFit
    from impctl.fit.household import FitOptions, choose_nights, fit_refusal, household_classes
    from impctl.fit.prior import with_class_probabilities
    from impctl.fit.result.report import fit_to_dict

    chosen = choose_nights(nights)
    if chosen.too_little() is not None:
        return None
    classes = household_classes(chosen.cut, model_dir)
    est = NightFit(**FitOptions().estimator_params())
    est.prior = with_class_probabilities(est.prior, classes.probabilities)
    est.fit(chosen.nights, classes.ranges)
    if fit_refusal(est) is not None:
        return None
    return fit_to_dict(est, classes.classes, classes.notes)


def campaign_fits(houses, n: int, model_dir, cache: Path, refit: bool, params=None,
                  tag: str = "") -> list[dict | None]:
    """Every household's fit JSON (cached; ``params``: the plant's realism, None: drawn)."""
    path = cache / f"fits-{n}{tag}.json"
    if path.exists() and not refit:
        return json.loads(path.read_text())
    from impctl.population.imp_run.synth import sample_nights

    sched = val_schedule(n)
    realism = None if params is None else (tag, params, True)
    sim, sp, _ = simulate_schedule(houses, sched, "realistic", realism, stop_at_t_min=True)
    gate = gateway_campaign(sp, sched)
    fits = []
    t0 = time.perf_counter()
    for i in range(n):
        nights = sample_nights(sim, sp, sched, i, sample_step_s=300.0, quantise_k=0.1,
                               power_noise=0.0, seed=VAL_SEED + i)
        used = iter(gate["used"][:, i])
        nights = [x for x in nights if x.kind != "constrained" or next(used)]
        try:
            fits.append(fit_json(nights, model_dir))
        except Exception as exc:  # noqa: BLE001 - a household the fit cannot take
            print(f"  house {i}: fit failed: {exc!r}", flush=True)
            fits.append(None)
        if (i + 1) % 20 == 0:
            print(f"  fitted {i + 1}/{n} ({time.perf_counter() - t0:.0f} s)", flush=True)
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(fits))
    return fits


def with_options(params, options: list[str], n: int):
    """``params`` with each ``SECTION.FIELD=VALUE`` of ``options`` set for every household (the
    plant's own range check applies)."""
    for option in options:
        key, _, value = option.partition("=")
        section, _, name = key.partition(".")
        part = getattr(params, section)
        params = replace(params, **{section: replace(part, **{name: np.full(n, float(value))})})
    return params


def boot_median(x: np.ndarray, rng: np.random.Generator) -> tuple[float, float, float]:
    """Median and its 95 % bootstrap interval (households resampled)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if not len(x):
        return (np.nan, np.nan, np.nan)
    meds = np.median(rng.choice(x, size=(BOOT, len(x)), replace=True), axis=1)
    return float(np.median(x)), *np.quantile(meds, [0.025, 0.975])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--households", type=int, default=200)
    ap.add_argument("--learn-days", type=int, default=21)
    ap.add_argument("--winter-days", type=int, default=75)
    ap.add_argument("--dt", type=float, default=60.0)
    ap.add_argument("--margin-k", type=float, default=1.0)
    ap.add_argument("--model-dir", default=None)
    ap.add_argument("--cache", type=Path, default=Path("out/bench-curve"))
    ap.add_argument("--refit", action="store_true")
    ap.add_argument("--oracle", action="store_true",
                    help="also the winter with the true house's own curve (its true heat "
                         "loss, night gain and emitter, as a straight line, no margin) where it "
                         "lowers the installer's: what perfect knowledge would save")
    ap.add_argument("--verbose", action="store_true",
                    help="one line per household whose curve impctl changed")
    ap.add_argument("--constant-flow", action="store_true",
                    help="every installer holds one flow temperature whatever the weather (the "
                         "built-in curve's flow at the house's design outdoor temperature) "
                         "instead of a heating curve")
    ap.add_argument("--no-watch", action="store_true",
                    help="impctl's curves without the daemon's comfort watch (which raises a "
                         "curve 1 K when the room stays 0.5 K short for an hour)")
    ap.add_argument("--plant", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                    help="set one realism option of every household, within the plant's range "
                         "(e.g. heat_pump.curve_gain=1.3: every installer's curve at 1.3 x the "
                         "house's matched curve); repeatable; default: the drawn realism")
    args = ap.parse_args()
    n = args.households
    command = "python bench/curve.py " + " ".join(sys.argv[1:])
    houses = sample_households(n, seed=VAL_SEED)
    params = sample_params(n, VAL_SEED)
    try:
        params = with_options(params, args.plant, n)
    except (AttributeError, TypeError, ValueError, InputError) as exc:
        ap.error(f"--plant: {exc}")
    t_start = time.perf_counter()
    core = PlantCore(houses, params, seed=0)
    installer = None  # the plant's own curve
    if args.constant_flow:
        design = np.broadcast_to(np.asarray(params.emitter.design_t_out_c, float), (n,))
        const = installer_flow_c(core, design)
        installer = (const, const.copy())
    learn = simulate(houses, params, args.learn_days, LEARN_SEED, "2026-11-20 00:00",
                     dt_s=args.dt, row_step_s=300.0, curve=installer)
    print(f"owner's nights simulated ({time.perf_counter() - t_start:.0f} s)", flush=True)
    tag = "".join(f"-{o}" for o in sorted(args.plant))
    fits = campaign_fits(houses, n, args.model_dir, args.cache, args.refit,
                         params if args.plant else None, tag)
    print(f"fits: {sum(f is not None for f in fits)}/{n} "
          f"({time.perf_counter() - t_start:.0f} s)", flush=True)
    fa, fb = np.full(n, np.nan), np.full(n, np.nan)
    central0, rec0, run0, timing = (np.full(n, np.nan) for _ in range(4))
    said = np.full((n, 3), np.nan)  # impctl's saving in % of the running curve's: value, 95 %
    reasons: dict[str, int] = {}
    advice = 0
    for j in range(n):
        t0 = time.perf_counter()
        try:
            res = analyse(rows_from_table(learn.house_rows(j), f"house {j}"), fits[j],
                          setpoint_c=SETPOINT_C, margin_k=args.margin_k, seed=j)
        except Exception as exc:  # noqa: BLE001
            reasons[type(exc).__name__] = reasons.get(type(exc).__name__, 0) + 1
            continue
        timing[j] = time.perf_counter() - t0
        nc = res.need_curve
        central0[j] = float(np.interp(0.0, nc.t_out_c, nc.central_c))
        rec0[j] = float(res.recommended.at(0.0))
        run0[j] = float(res.running.line.at(0.0)) if res.running else np.nan
        if res.savings is not None and res.savings.running_kwh > 0:
            sv = res.savings
            said[j] = 100.0 * np.array([sv.saving_kwh, sv.saving_low_kwh, sv.saving_high_kwh]) \
                / sv.running_kwh
        line = res.recommended
        if res.lowers and writable(line, res.running.line if res.running else None):
            fa[j], fb[j] = line.flow_a_c, line.flow_b_c
        elif res.lowers:
            advice += 1
    print(f"analysed ({time.perf_counter() - t_start:.0f} s); refused: {reasons or 'none'}; "
          f"lower, but advice only (a point above {FLOW_LIMITS_C[1]:g} °C and the running "
          f"curve's): {advice}", flush=True)
    changed = np.isfinite(fa)
    truth0 = true_flow_c(core, learn.night_gain_w, 0.0)
    owner = installer or tuple(installer_flow_c(core, t) for t in POINTS_T_OUT_C)
    inst0 = installer[0] if installer else installer_flow_c(core, 0.0)

    def run_winter(curve_a, curve_b):
        """The winter with these curves where finite, the installer's elsewhere."""
        mask = np.isfinite(curve_a)
        if installer:
            curve_a, curve_b = np.where(mask, curve_a, owner[0]), np.where(mask, curve_b, owner[1])
        watch = None if args.no_watch else Watch(owner, mask.copy(), installer is None)
        return simulate(houses, params, args.winter_days, WINTER_SEED, "2027-01-05 00:00",
                        dt_s=args.dt, curve=(curve_a, curve_b), watch=watch)

    base = simulate(houses, params, args.winter_days, WINTER_SEED, "2027-01-05 00:00",
                    dt_s=args.dt, curve=installer)
    ours = run_winter(fa, fb)
    print(f"winters simulated ({time.perf_counter() - t_start:.0f} s)\n", flush=True)
    report(args, command, params, base, ours, changed, central0, rec0, run0, truth0, inst0,
           timing)
    said_and_done(params, base, ours, changed, said)
    if args.oracle:
        ofa, ofb = oracle_curves(core, learn.night_gain_w, inst0, owner)
        known = run_winter(ofa, ofb)
        print("\n=== the true house's own curve (perfect knowledge, no margin) ===")
        report(args, command, params, base, known, np.isfinite(ofa), central0, rec0, run0,
               truth0, inst0, timing)


def said_and_done(params, base, ours, changed: np.ndarray, said: np.ndarray) -> None:
    """What ``impctl curve`` said lowering would save (% of the running curve's electricity,
    its 95 % interval) against what the winter saved, on the households it changed."""
    done = 100.0 * (1.0 - ours.electricity_kwh / base.electricity_kwh)
    control = np.broadcast_to(np.asarray(params.heat_pump.control), (len(changed),))
    print("\nthe saving impctl said (its 95 % interval) against the winter's, changed households:")
    for name, m in (("weather curve", changed & (control == 0)),
                    ("room thermostat", changed & (control == 1))):
        m = m & np.isfinite(said[:, 0])
        if not m.any():
            continue
        inside = (said[m, 1] <= done[m]) & (done[m] <= said[m, 2])
        below = done[m] < said[m, 1]
        print(f"  {name:16s} {m.sum():3d}: said median {np.median(said[m, 0]):+5.1f} %, saved "
              f"{np.median(done[m]):+5.1f} %; the winter's inside the said interval in "
              f"{100 * inside.mean():.0f} %, below it in {100 * below.mean():.0f} %")


def oracle_curves(core: PlantCore, night_gain_w: np.ndarray, inst0: np.ndarray,
                  owner: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Each house's own curve from its truth (the need on the grid as both the central and the
    bound, no margin, the same straight-line rule over the assumed winter), where it is at
    least 0.5 K below the installer's at 0 °C; NaN elsewhere."""
    from impctl.curve.need import GRID_T_OUT_C, Line, NeedCurve, recommend
    from impctl.curve.savings import ASSUMED_DAYS
    from impctl.weather import winter_weather

    climate = winter_weather(days=ASSUMED_DAYS, step_s=3600, seed=0).to_numpy()
    idx = np.clip(np.rint((climate - GRID_T_OUT_C[0]) / 0.5), 0, len(GRID_T_OUT_C) - 1)
    fa, fb = np.full(core.n, np.nan), np.full(core.n, np.nan)
    need = np.array([true_flow_c(core, night_gain_w, float(t)) for t in GRID_T_OUT_C])
    cold, mild = owner
    for j in range(core.n):
        q = np.maximum(core.hlc[j] * (SETPOINT_C - climate) - night_gain_w[j], 0.0)
        weights = np.bincount(idx.astype(int), weights=q, minlength=len(GRID_T_OUT_C))
        curve = NeedCurve(GRID_T_OUT_C, need[:, j], need[:, j], q)
        line = recommend(curve, 0.0, weights, SETPOINT_C, float(np.quantile(climate, 0.01)),
                            0.0)
        if line.at(0.0) <= inst0[j] - 0.5 and writable(line, Line(cold[j], mild[j])):
            fa[j], fb[j] = line.flow_a_c, line.flow_b_c
    return fa, fb


def report(args, command, params, base, ours, changed, central0, rec0, run0, truth0, inst0,
           timing) -> None:
    """Print the tables."""
    rng = np.random.default_rng(0)
    n = len(changed)
    d_el = 100.0 * (ours.electricity_kwh / base.electricity_kwh - 1.0)
    cop_b = base.heat_kwh / base.electricity_kwh
    cop_o = ours.heat_kwh / ours.electricity_kwh
    d_cold = 100.0 * (ours.cold_h - base.cold_h) / base.hours
    d_seen = 100.0 * (ours.cold_sensed_h - base.cold_sensed_h) / base.hours
    kind = np.broadcast_to(np.asarray(params.emitter.kind), (n,))
    control = np.broadcast_to(np.asarray(params.heat_pump.control), (n,))
    groups = {"all": np.ones(n, bool), "radiators": kind == 0, "underfloor": kind == 1,
              "weather curve": control == 0, "room thermostat": control == 1,
              "curve changed": changed, "changed, curve": changed & (control == 0),
              "changed, thermo": changed & (control == 1)}
    print(f"command: {command}")
    print(f"{n} households, {args.winter_days}-day winter at {args.dt:g} s, margin "
          f"{args.margin_k:g} K; impctl changed the curve of {changed.sum()} "
          f"({100 * changed.mean():.0f} %)\n")
    head = (f"{'group':16s} {'n':>4s}  {'Δ electricity % [95 % CI]':>30s}  "
            f"{'Δ COP [95 % CI]':>26s}  {'Δ cold h % of h [95 % CI]':>30s}")
    print(head)
    for name, m in groups.items():
        if not m.any():
            continue
        e = boot_median(d_el[m], rng)
        c = boot_median((cop_o - cop_b)[m], rng)
        k = boot_median(d_cold[m], rng)
        print(f"{name:16s} {m.sum():4d}  {e[0]:+8.2f} [{e[1]:+6.2f}, {e[2]:+6.2f}]        "
              f"{c[0]:+6.3f} [{c[1]:+6.3f}, {c[2]:+6.3f}]  "
              f"{k[0]:+7.2f} [{k[1]:+6.2f}, {k[2]:+6.2f}]")
    print()
    print(f"cold hours (< {SETPOINT_C - 0.5:g} °C) % of heating hours: installer median "
          f"{np.median(100 * base.cold_h / base.hours):.2f}, impctl "
          f"{np.median(100 * ours.cold_h / ours.hours):.2f}; worst Δ "
          f"{np.max(d_cold):+.2f} pp; households with Δ > 1 pp: {(d_cold > 1).sum()}")
    print(f"as the room sensor reads (what the owner and the heat pump see): installer median "
          f"{np.median(100 * base.cold_sensed_h / base.hours):.2f} %, impctl "
          f"{np.median(100 * ours.cold_sensed_h / ours.hours):.2f} %; median Δ "
          f"{np.median(d_seen):+.2f} pp, worst {np.max(d_seen):+.2f} pp; households with Δ > 1 "
          f"pp: {(d_seen > 1).sum()}")
    print(f"coldest room: installer {np.min(base.coldest_c):.2f} °C, impctl "
          f"{np.min(ours.coldest_c):.2f} °C; nights below T_min {T_MIN_C:g} °C: installer "
          f"{(base.coldest_night_c < T_MIN_C).sum()}, impctl "
          f"{(ours.coldest_night_c < T_MIN_C).sum()} households "
          f"(changed by impctl: {((ours.coldest_night_c < T_MIN_C) & changed).sum()})")
    if ours.raises is not None:
        r = ours.raises[changed]
        print(f"comfort watch: raised {int((r > 0).sum())} of {int(changed.sum())} changed "
              f"curves ({int(r.sum())} raises of 1 K; {int((r >= 3).sum())} three times or "
              "more)")
    print(f"space-heating COP: installer median {np.median(cop_b):.2f}, impctl "
          f"{np.median(cop_o):.2f}; mean room: installer {np.median(base.mean_t_air_c):.2f} °C, "
          f"impctl {np.median(ours.mean_t_air_c):.2f} °C")
    ok = np.isfinite(central0)
    err_c = central0 - truth0
    err_r = rec0 - truth0
    print(f"\nflow at 0 °C against the true house's need ({ok.sum()} households analysed):")
    print(f"  impctl's central need:    median error {np.median(err_c[ok]):+.2f} K, median "
          f"|error| {np.median(np.abs(err_c[ok])):.2f} K, within 2 K: "
          f"{100 * np.mean(np.abs(err_c[ok]) <= 2):.0f} %")
    print(f"  the recommended curve:    median {np.median(err_r[ok]):+.2f} K above the need "
          f"(bound + margin + straight line), below it in {100 * np.mean(err_r[ok] < 0):.0f} %")
    print(f"  the installer's curve:    median {np.median((inst0 - truth0)[ok]):+.2f} K above "
          f"the need; read back by impctl from the flow target: median error "
          f"{np.nanmedian((run0 - inst0)[ok]):+.2f} K")
    for name, m in (("radiators", kind == 0), ("underfloor", kind == 1)):
        mm = m & ok
        print(f"  {name:10s} central |error| median {np.median(np.abs(err_c[mm])):.2f} K, "
              f"installer above need {np.median((inst0 - truth0)[mm]):+.2f} K")
    if args.verbose:
        print("\nhouseholds whose curve impctl changed:")
        for j in np.flatnonzero(changed):
            how = "thermostat" if control[j] else "curve"
            print(f"  {j:3d} {'UFH' if kind[j] else 'rad'} {how:10s}"
                  f" gain {float(np.ravel(params.heat_pump.curve_gain)[j]):.2f} room k "
                  f"{float(np.ravel(params.heat_pump.room_influence_k_per_k)[j]):.1f}: "
                  f"Δel {d_el[j]:+6.2f} %, Δcold {d_cold[j]:+5.2f} pp (sensor "
                  f"{d_seen[j]:+5.2f}); room sensor offset "
                  f"{float(np.ravel(params.sensors.t_air_offset_k)[j]):+.2f} K; at 0 °C need "
                  f"{truth0[j]:.1f}, installer {inst0[j]:.1f}, impctl {rec0[j]:.1f} °C; "
                  f"coldest night {base.coldest_night_c[j]:.1f} → {ours.coldest_night_c[j]:.1f} °C"
                  + ("" if ours.raises is None else f"; raised {ours.raises[j]}×"))
    t = timing[np.isfinite(timing)]
    print(f"\nimpctl curve analysis per household: median {np.median(t):.2f} s, max "
          f"{np.max(t):.2f} s")


if __name__ == "__main__":
    main()
