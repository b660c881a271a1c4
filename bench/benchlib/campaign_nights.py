"""The gateway's campaign nights, for the benches that simulate them (``bench/campaign.py``,
``bench/calibrate_intervals.py``).

The setpoints come from :class:`impctl.config.CampaignConfig`'s defaults — what a gateway runs
unless its owner configured otherwise — never from numbers written here, so a change of the
protocol there reaches the campaign bench and the few-nights calibration alike.
"""

from __future__ import annotations

from impctl.config import CampaignConfig
from impctl.population.imp_run.synth import imp_schedule


def variants(cfg: CampaignConfig | None = None) -> tuple[tuple[str, float], ...]:
    """(kind, setpoint °C) of every night a campaign can run: the constrained night at the
    constrained setpoint first, then a normal night at each normal setpoint, in order."""
    cfg = cfg or CampaignConfig()
    return ((("constrained", float(cfg.constrained_setpoint_c)),)
            + tuple(("normal", float(sp)) for sp in cfg.normal_setpoints_c))


def fixed_plan(cfg: CampaignConfig | None = None) -> tuple[int, ...]:
    """The fixed campaign as indices into :func:`variants`: the constrained nights first, then
    each normal setpoint's nights in turn (2 + 3 by default)."""
    cfg = cfg or CampaignConfig()
    normal = [1 + k for k in range(len(cfg.normal_setpoints_c))
              for _ in range(cfg.normal_nights_per_setpoint)]
    return (0,) * cfg.constrained_nights + tuple(normal)


def variant_schedule(n: int, k: int, kind: str, setpoint_c: float, seed: int):
    """``k`` nights of one variant for ``n`` houses (the seed's weather: every variant of a
    house sees the same outdoor temperatures, so night j of any variant is the same date)."""
    return imp_schedule(n, n_constrained=k if kind == "constrained" else 0,
                        n_normal=0 if kind == "constrained" else k, setpoints_c=(setpoint_c,),
                        constrained_setpoint_c=setpoint_c, seed=seed)


def parse_sequence(text: str, cfg: CampaignConfig | None = None) -> tuple[int, ...]:
    """A night sequence "c.n0.n-1" → indices into :func:`variants` (``c``: constrained,
    ``nK``: normal at the K-th normal setpoint, Python indexing, so ``n-1`` is the warmest
    when the setpoints rise)."""
    cfg = cfg or CampaignConfig()
    n_normal = len(cfg.normal_setpoints_c)
    out = []
    for token in text.split("."):
        if token == "c":
            out.append(0)
        elif token.startswith("n") and token[1:].lstrip("-").isdigit() \
                and -n_normal <= int(token[1:]) < n_normal:
            out.append(1 + int(token[1:]) % n_normal)
        else:
            raise ValueError(f"night sequence {text!r}: {token!r} is neither 'c' nor 'nK' "
                             f"with K in {-n_normal}..{n_normal - 1}")
    return tuple(out)


def label(sequence: tuple[int, ...], cfg: CampaignConfig | None = None) -> str:
    """"c21 n21 n23": the kinds and setpoints [°C] of a sequence."""
    v = variants(cfg)
    return " ".join(f"{v[i][0][0]}{v[i][1]:g}" for i in sequence)


def night_sources(cfg: CampaignConfig | None = None) -> tuple[tuple[int, int | None], ...]:
    """What a replayed night was simulated after, as (variant, previous variant or None), indices
    into :func:`variants`: first each variant after a night of its own kind (``None``: the
    pre-simulated schedules of one variant, every night of the same kind), then a constrained
    night after a normal night at each normal setpoint, then a normal night at each normal
    setpoint after a constrained night (:func:`alternating_schedule`)."""
    n = len(variants(cfg))
    return (tuple((v, None) for v in range(n)) + tuple((0, p) for p in range(1, n))
            + tuple((p, 0) for p in range(1, n)))


def source_of(v: int, previous: int | None, sources: tuple) -> int:
    """The index in ``sources`` (:func:`night_sources`) of variant ``v`` run the night after
    variant ``previous`` (None: no night the date before). A night after one of its own kind,
    or after no night, replays the one-variant schedule: the house state a normal night at
    another setpoint leaves differs by ±1 K of held temperature, not by a night of cooling."""
    key = (v, previous) if (v, previous) in sources else (v, None)
    return sources.index(key)


def alternating_schedule(n: int, k: int, constrained_c: float, normal_c: float,
                         constrained_parity: int, seed: int):
    """``k`` nights alternating constrained (on the dates whose index has parity
    ``constrained_parity``) and normal at ``normal_c`` [°C], the seed's weather (the same dates'
    as :func:`variant_schedule`'s: the same length, so the same outdoor temperatures)."""
    order = ["constrained" if j % 2 == constrained_parity else "normal" for j in range(k)]
    return imp_schedule(n, n_constrained=order.count("constrained"),
                        n_normal=order.count("normal"), setpoints_c=(normal_c,),
                        constrained_setpoint_c=constrained_c, seed=seed, order=order)
