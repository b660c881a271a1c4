"""Calibrate the fit's model-error share on the realistic virtual population (and explain misses).

Run (regenerates ``src/impctl/fit/intervals/model_error.json``; about 1,350 fits in about 5 min on
one core, batched, a line per batch of 16)::

    OMP_NUM_THREADS=1 .venv/bin/python bench/calibrate_intervals.py [--households 160]
        [--seed 31415] [--steps 300:160,3600:160] [--sequences c.n0,c.n0.n-1,…]

Households: ``sample_households(N, seed)`` with realism ``sample_params(N, seed)`` on the
realistic plant, each with the bench's IMP protocol (2 constrained + 6 normal nights, 5-minute
rows, true class ranges) — the seed must differ from the bench's validation seed (20260) and the
classifiers' training seeds (``impctl train --seed 0``). Each house is fitted with the share
switched off (``NightFit(model_error=None)``); its diagnostics, interval SDs and log errors go to
the calibration (:func:`impctl.fit.intervals.model_error.calibrate`): the "many nights" band.
At the first (finest) step each house is also fitted on the nights a campaign on a gateway
ends on (``--sequences``, :data:`SEQUENCES`): every variant of a campaign night — constrained
at ``CampaignConfig().constrained_setpoint_c``, normal at each of its ``normal_setpoints_c``,
the gateway's pre-heat — simulated on the house's own weather and gains, as
``bench/campaign.py`` does; these fits calibrate the "few nights" band, whose file records the
setpoints (``bands.few.protocol``). Until h18c the few band took the first C + N nights of the
2 + 6 protocol above (normal 22 °C, constrained 23 °C, normal 24, 22 °C, …, the second
constrained night at 24 °C), nights a campaign never runs.

``--why`` (with ``--seed 20260`` for the bench's held-out houses): fit with the share ON and print,
for every house whose interval misses a truth, what the fit could see (the "why do intervals
miss" table); writes no calibration.
``--records FILE`` keeps the per-house records (JSON) and ``--from-records FILE`` recalibrates
from them without fitting.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from benchlib import campaign_nights  # the gateway's nights, as bench/campaign.py
from benchlib.fit_tables import interval_record, why_table
from fit import (  # bench/fit.py: the same protocol
    ACH,
    VAL_SEED,
    _sub_schedule,
    gateway_campaign,
    true_ranges,
)

from impctl.config import CampaignConfig
from impctl.fit.intervals import model_error
from impctl.fit.optim.batch import fit_households
from impctl.imp.protocol import DEFAULT_BAND_K, MIN_NIGHT_H
from impctl.model import HouseParameters
from impctl.population.households import sample_households
from impctl.population.imp_run.synth import (
    imp_schedule,
    run_schedule,
    run_schedule_plant,
    sample_nights,
)
from impctl.population.realism import sample_params, take_params

TRAIN_SEEDS = (0,)
#: The few-nights band's campaign night sequences (``--sequences``): the endings of the
#: adaptive campaign (``bench/campaign.py`` prints them; the same on seeds 20260 and 4242: a
#: constrained night, a normal one at the first setpoint — the default order — then mostly the
#: last setpoint, a second constrained night now and then; the 2-night fits are those the floor
#: rule stops) and the fixed 2 + 3 plan.
SEQUENCES = ("c.n0,c.n0.c,c.n0.n-1,c.n0.n-1.c,c.n0.n-1.n-1,c.n0.n-1.n-1.c,c.n0.n-1.n-1.n-1,"
             "c.c.n0.n1.n2")
CHUNK = 40   # households simulated together (memory, and a progress line per chunk)


def _truth(house) -> dict[str, float]:
    return {"hlc": house.hlc_w_per_k, "c_m": house.c_m_j_per_k, "tau": house.tau_h}


def _used_variant_nights(usable_h: np.ndarray, sequence: tuple[int, ...]) -> list[int] | None:
    """Night index per position of ``sequence`` (indices into the variants) as a gateway gets
    them: a constrained night at position j is the first valid one (``usable_h`` [h] per
    constrained variant night ≥ MIN_NIGHT_H) from night j on not used yet — the gateway
    repeats an invalid one on a later night; -1 where none is left (the night is missing from
    the fit); None when no constrained night is valid (the gateway does not fit)."""
    valid = list(usable_h >= MIN_NIGHT_H - 1e-9)
    out, taken = [], set()
    for j, v in enumerate(sequence):
        if v != 0:
            out.append(j)
            continue
        k = next((k for k in range(j, len(valid)) if valid[k] and k not in taken), -1)
        taken.add(k)
        out.append(k)
    return out if any(k >= 0 for k, v in zip(out, sequence, strict=True) if v == 0) else None


def collect(n: int, seed: int, steps: dict[float, int], share_on: bool,
            plant: str = "realistic", sequences: tuple[tuple[int, ...], ...] = (),
            batch: int = 16, gateway: bool = True) -> list[dict]:
    """Simulate ``n`` households (realistic plant, or ``plant="iso"``: the ideal 5R1C with the
    bench's 5 % power noise) and fit the first ``steps[step]`` of them at each sample step [s]
    on the 2 + 6 protocol (the "many" band); at the first step also each of ``sequences``
    (campaign night sequences, indices into :func:`campaign_nights.variants`: the gateway's
    nights, the "few" band). One record per fit; fits in batches of ``batch`` households
    (:func:`impctl.fit.optim.batch.fit_households`, the same numbers as single fits).
    ``gateway``: constrained nights end as the gateway ends them (T_min or its anticipation,
    then the day setpoint) and the fit gets only the valid ones, an invalid one repeated on a
    spare night (``campaign.max_invalid_nights`` of them); a household with no valid
    constrained night is not fitted (the gateway waits for one). False: every constrained night
    cools to 05:00 (the calibration before branch h14w)."""
    houses = sample_households(n, seed=seed)
    params = sample_params(n, seed)
    kind = np.broadcast_to(np.asarray(params.emitter.kind), (n,))
    onoff = np.broadcast_to(np.asarray(params.heat_pump.min_modulation), (n,)) >= 0.999
    control = np.broadcast_to(np.asarray(params.heat_pump.control), (n,))
    spares = CampaignConfig().max_invalid_nights if gateway else 0
    sched = imp_schedule(n, seed=seed, n_spare_constrained=spares)
    variants = campaign_nights.variants()
    k = max((len(q) for q in sequences), default=0)
    var_sched = [campaign_nights.variant_schedule(n, k + (spares if kd == "constrained" else 0),
                                                  kd, sp, seed) for kd, sp in variants] \
        if k else []
    skipped = {"all": 0, "few": 0}
    records = []
    started = time.perf_counter()
    t_sim = 0.0
    first_step = next(iter(steps))
    n_fits = sum(min(n, c) for c in steps.values()) + len(sequences) * min(n, steps[first_step])
    noise = 0.05 if plant == "iso" else 0.0

    def simulate(sch, idx, i):
        sub = _sub_schedule(sch, idx)
        chunk = HouseParameters.stack([houses.take(int(h)) for h in idx])
        if plant == "iso":
            return (*run_schedule(chunk, sub, stop_at_t_min=gateway), sub)
        return (*run_schedule_plant(chunk, sub, take_params(params, idx, n), seed=seed + i,
                                    stop_at_t_min=gateway), sub)

    for i0 in range(0, n, CHUNK):   # simulate the next chunk of houses together
        t0 = time.perf_counter()
        idx = np.arange(i0, min(n, i0 + CHUNK))
        logged, sp, sub = simulate(sched, idx, i0)
        var_sims = [simulate(vs, idx, i0) for vs in var_sched]
        t_sim += time.perf_counter() - t0
        used = gateway_campaign(sp, sub)["used"]
        var_usable = (gateway_campaign(var_sims[0][1], var_sims[0][2])["usable_h"]
                      if var_sims else None)
        jobs = []   # (house, step, label, nights)
        for step_s, count in steps.items():
            for i in idx[idx < count]:
                def cut(sim, spc, sch, i=int(i), step_s=step_s):
                    return sample_nights(sim, spc, sch, i % CHUNK, sample_step_s=step_s,
                                         quantise_k=0.1, seed=seed + i, power_noise=noise)
                keep = iter(used[:, i % CHUNK])
                nights = [x for x in cut(logged, sp, sub)
                          if x.kind != "constrained" or next(keep)]
                if any(x.kind == "constrained" for x in nights):
                    jobs.append((int(i), step_s, "all", nights))
                else:
                    skipped["all"] += 1
                if step_s != first_step:
                    continue
                per_variant = [cut(*vs) for vs in var_sims]
                for q in sequences:
                    at = _used_variant_nights(var_usable[:, i % CHUNK], q)
                    if at is None:
                        skipped["few"] += 1
                        continue
                    jobs.append((int(i), step_s, campaign_nights.label(q),
                                 [per_variant[v][j] for j, v in zip(at, q, strict=True)
                                  if j >= 0]))
        for b in range(0, len(jobs), batch):
            part = jobs[b:b + batch]
            fits, _ = fit_households([j[3] for j in part],
                                     [true_ranges(houses.take(j[0])) for j in part],
                                     ach_vent=ACH[0], ach_infl=ACH[1],
                                     model_error="default" if share_on else None)
            for (i, step_s, label, _), fit in zip(part, fits, strict=True):
                if isinstance(fit, BaseException):
                    print(f"  house {i:3d}, nights {label}: fit failed ({fit}); left out",
                          flush=True)
                    continue
                records.append(interval_record(i, step_s, fit, _truth(houses.take(i)), kind[i],
                                       onoff[i], control[i]))
                records[-1]["nights"] = label
            rec = records[-1]
            print(f"  fit {len(records):4d}/{n_fits}: house {part[-1][0]:3d}, "
                  f"{part[-1][1]:4.0f} s rows, nights {part[-1][2]}, "
                  f"{model_error.band_of(rec['diagnostics']):4s} "
                  f"{model_error.group_of(rec['diagnostics']):8s} log error HLC/τ/C_m "
                  + " ".join(f"{100 * rec['log_error'][q]:+6.1f}" for q in ("hlc", "tau", "c_m"))
                  + f" %  ({time.perf_counter() - started:.0f} s, of which simulation "
                    f"{t_sim:.0f} s)", flush=True)
    if gateway:
        print(f"not fitted (no valid constrained night: the gateway would not fit them): "
              f"{skipped['all']} 2 + 6 campaigns, {skipped['few']} campaign sequences",
              flush=True)
    return records


def provenance(args, n: int) -> dict:
    def git(*a):
        try:
            return subprocess.run(["git", *a], capture_output=True, text=True, check=True,
                                  cwd=Path(__file__).resolve().parents[1]).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    return {"seed": args.seed, "n_households": args.households, "n_fits": n,
            "steps": args.steps, "sequences": args.sequences,
            "ranges": "true class", "plant": "impctl.plant realistic, realism "
            "sample_params(N, seed)", "plant_commit": git("log", "-1", "--format=%h", "--",
                                                           "src/impctl/plant"),
            "fit_commit": git("log", "-1", "--format=%h", "--", "src/impctl/fit"),
            "protocol_commit": git("log", "-1", "--format=%h", "--",
                                   "src/impctl/population/synth_nights.py", "src/impctl/imp"),
            "created": dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%MZ"),
            "command": "python bench/calibrate_intervals.py --households "
                       f"{args.households} --seed {args.seed} --steps {args.steps} --sequences "
                       f"{args.sequences}"}


def summary(records: list[dict], cal: dict | None) -> None:
    print("\n### calibration records: per band and group, median |error| % and coverage without "
          "the share")
    for band in model_error.BANDS:
        for name in model_error.GROUPS:
            rs = [r for r in records if model_error.band_of(r["diagnostics"]) == band
                  and model_error.group_of(r["diagnostics"]) == name]
            if not rs:
                print(f"  {band:4s} {name:8s} n=  0")
                continue
            cells = []
            for q in model_error.QUANTITIES:
                e = np.median([abs(r["log_error"][q]) for r in rs]) * 100
                c = np.mean([r["covered"][q] for r in rs]) * 100
                s = (cal["bands"][band]["groups"][name]["share"][q] * 100 if cal
                     else float("nan"))
                cells.append(f"{q} {e:5.1f} % cov {c:3.0f} % share {s:5.1f} %")
            print(f"  {band:4s} {name:8s} n={len(rs):3d}: " + "; ".join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=160)
    ap.add_argument("--seed", type=int, default=31415)
    ap.add_argument("--steps", default="300:160,3600:160",
                    help="sample steps [s] and how many of the households each, STEP:N,…")
    ap.add_argument("--sequences", default=SEQUENCES,
                    help="campaign night sequences fitted too at the first step (the "
                         "few-nights band), comma-separated, each of c (constrained) and nK "
                         "(normal at the K-th normal setpoint of CampaignConfig, n-1 the "
                         "last) joined by dots; empty for none")
    ap.add_argument("--plant", choices=("realistic", "iso"), default="realistic",
                    help="iso: the ideal 5R1C (a check; never written as the calibration)")
    ap.add_argument("--cool-to-window-end", dest="gateway", action="store_false",
                    help="constrained nights cool to 05:00, every one fitted (the calibration "
                         "before branch h14w; never the gateway's nights)")
    ap.add_argument("--out", default=str(model_error.CALIBRATION_FILE))
    ap.add_argument("--records", default=None, help="also write the per-house records here")
    ap.add_argument("--from-records", default=None, help="recalibrate from saved records")
    ap.add_argument("--why", action="store_true",
                    help="fit with the share on and print the miss table; no calibration")
    ap.add_argument("--share", choices=("on", "off"), default=None,
                    help="model-error share in the fits (default: on with --why, else off)")
    args = ap.parse_args()
    print("command: " + " ".join(["python"] + sys.argv), flush=True)
    steps = {float(a): int(b) for a, b in (x.split(":") for x in args.steps.split(",") if x)}
    try:
        sequences = tuple(campaign_nights.parse_sequence(x) for x in args.sequences.split(",")
                          if x)
    except ValueError as exc:
        ap.error(f"--sequences: {exc}")
    if args.from_records:
        records = json.loads(Path(args.from_records).read_text())
    else:
        if not args.why and (args.seed == VAL_SEED or args.seed in TRAIN_SEEDS):
            ap.error(f"--seed {args.seed} is the bench's validation or a training seed")
        share_on = args.why if args.share is None else args.share == "on"
        records = collect(args.households, args.seed, steps, share_on, args.plant, sequences,
                          gateway=args.gateway)
    if args.records:
        Path(args.records).write_text(json.dumps(records))
    if args.why or args.plant == "iso":
        why_table(records)
        summary(records, None)
        return
    cfg = CampaignConfig()
    protocol = {"constrained_setpoint_c": float(cfg.constrained_setpoint_c),
                "normal_setpoints_c": [float(x) for x in cfg.normal_setpoints_c],
                "sequences": sorted({r["nights"] for r in records if r["nights"] != "all"}),
                "band_k": DEFAULT_BAND_K,
                "constrained_nights": ("gateway: end at T_min or its anticipation, valid with "
                                       f"≥ {MIN_NIGHT_H:g} h after the lag, invalid ones "
                                       "repeated" if getattr(args, "gateway", True)
                                       else "cool to the window's end")}
    cal = model_error.calibrate(records, provenance(args, len(records)), protocol=protocol)
    summary(records, cal)
    if not all(np.isfinite(v) for b in cal["bands"].values() for g in b["groups"].values()
               for v in g["share"].values()):
        sys.exit(f"not written: {len(records)} fits are too few for a 95 % conformal share "
                 f"(≥ {model_error.MIN_GROUP} per group, or pooled)")
    Path(args.out).write_text(json.dumps(cal, indent=1) + "\n")
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
