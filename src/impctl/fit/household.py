"""One household's nights as the fit takes them — read, checked, chosen, classified — and its
finished fit checked: ONE path for ``impctl fit`` and for every household of
``impctl fleet fit``. A file one of them refuses the other refuses with the same line, and both
fit the same nights in the same search box with the same prior, so a fleet row's numbers equal
``impctl fit``'s on the same file with the same options.

1. :func:`read_household` — the size guard before anything is read (:func:`guard_household`,
   :mod:`impctl.imp.files.limits`), the NIGHTS file read, then
   :func:`check_household` — the unit plausibility (:func:`impctl.imp.plausibility.check_units`:
   q_hc in kW, a ratio of power to temperature difference no dwelling has);
2. :func:`choose_nights` — the nights cut at gaps (:mod:`impctl.imp.gaps`), the usable ones,
   the most recent ``max_nights``, and which kind of night is missing (:meth:`ChosenNights.
   too_little`: the refusal);
3. :func:`household_classes` — the classifiers' ranges and class probabilities, or the whole
   prior ranges said in a note;
4. after the fit, :func:`fit_refusal` — a fit no house gives (an HLC outside a dwelling's, a
   model that misses its own nights' heat) is a unit or column problem, not a result.

Light at import (no numpy, torch or scikit-learn until a function runs): the CLI imports it.
To add an option that changes the numbers, add it to :class:`FitOptions` (and, if the
estimator takes it, to :meth:`FitOptions.estimator_params`); both commands pass it through.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..imp.files.limits import refuse_large_file
from ..imp.protocol import MIN_NIGHT_H, Q_ON_W

#: Nights fitted by default / accepted by ``--max-nights``: the fit's memory and time grow
#: about linearly with the nights (bench/fit_large.py); an IMP campaign has 5–8.
DEFAULT_MAX_NIGHTS = 30
MAX_NIGHTS_RANGE = (2, 120)
_NEEDS = {
    "constrained": "a constrained night (heating off; at least {h:g} h of cooling after the "
                   "{lag:g} h emission lag) — it carries the time constant τ",
    "normal": "a normal night (setpoint held, heat power logged, at least {h:g} h) — it carries "
              "the absolute scale: HLC and C_m",
}


@dataclass(frozen=True)
class FitOptions:
    """The options that decide a household's numbers, the same for ``impctl fit`` and
    ``impctl fleet fit`` (units as the estimator's: air changes [1/h], night gain [W])."""

    normal_model: str = "demand"
    timestamps: str = "instant"
    ach_infl: float = 0.01
    ach_vent: float = 0.0
    max_nights: int = DEFAULT_MAX_NIGHTS
    #: declared night gain [W] and its SD [W]; None: not declared (measured from the nights'
    #: columns, else estimated, else assumed — :mod:`impctl.fit.gain`)
    night_gain_w: float | None = None
    night_gain_sd_w: float | None = None
    #: declared SD of the indoor / outdoor sensor's offset [K] and the heat meter's error
    #: (a fraction); None: assumed (:mod:`impctl.fit.checks.instruments`)
    t_air_offset_sd_k: float | None = None
    t_out_offset_sd_k: float | None = None
    meter_error: float | None = None

    def estimator_params(self) -> dict[str, Any]:
        """The :class:`~impctl.fit.NightFit` constructor parameters among these options."""
        offsets = (None if self.t_air_offset_sd_k is None and self.t_out_offset_sd_k is None
                   else (self.t_air_offset_sd_k, self.t_out_offset_sd_k))
        return {"normal_model": self.normal_model, "timestamps": self.timestamps,
                "ach_infl": self.ach_infl, "ach_vent": self.ach_vent,
                "night_gain_w": self.night_gain_w, "night_gain_sd_w": self.night_gain_sd_w,
                "sensor_offsets_k": offsets, "meter_error": self.meter_error}

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready (the fleet's manifest keeps them: a resumed run must use the same)."""
        return dataclasses.asdict(self)


class Refusal(InputError):
    """A household's input refused: the line ``impctl fit`` prints (``str``), and a short
    ``reason`` a fleet's rows and report group by: "too large", "unreadable input",
    "implausible units", "implausible fit"."""

    def __init__(self, reason: str, error: InputError):
        super().__init__(error.problem, error.source, error.place)
        self.reason = reason

    def __reduce__(self):  # pickled as the plain InputError it reads as
        return InputError, (self.problem, self.source, self.place)


def _refused(reason: str, error: InputError) -> Refusal:
    return error if isinstance(error, Refusal) else Refusal(reason, error)


def guard_household(source: str | Path, rows: int | None = None) -> None:
    """Refuse, before anything is read, a household too large to read: a file above
    :data:`impctl.imp.files.limits.MAX_FILE_MB` (a NIGHTS.csv), or ``rows`` (counted in a Parquet
    file's or dataset's metadata) above :data:`impctl.imp.files.limits.MAX_ROWS`."""
    from ..imp.files.limits import refuse_many_rows

    try:
        if rows is None:
            refuse_large_file(source)
        else:
            refuse_many_rows(rows, source)
    except InputError as exc:
        raise _refused("too large", exc) from None


def read_household(path: str | Path, tz: str, *,
                   read_frame: Callable[[], Any] | None = None) -> list:
    """A household's nights as ``impctl fit`` reads them, checked (:func:`check_household`).

    Without ``read_frame``: the NIGHTS.csv ``path``, refused first when too large
    (:func:`guard_household`). With it: the NIGHTS columns of the DataFrame it returns (a
    fleet's Parquet rows; guard them with :func:`guard_household` before reading them),
    errors naming ``path``.

    Raises
    ------
    Refusal
        Too large, unreadable, or implausible units — one line naming the file.
    """
    from ..imp.files.nights_csv import read_nights, read_nights_frame

    try:
        if read_frame is None:
            guard_household(path)
            nights = read_nights(path, tz)
        else:
            nights = read_nights_frame(read_frame(), path, tz)
    except InputError as exc:
        raise _refused("unreadable input", exc) from None
    return check_household(nights, path)


def check_household(nights: Sequence, source: str | Path) -> list:
    """``nights`` if their heat output can be in W for the measured temperatures, else the
    refusal of :func:`impctl.imp.plausibility.check_units` (naming ``source``)."""
    from ..imp.plausibility import check_units

    try:
        check_units(nights, source)
    except InputError as exc:
        raise _refused("implausible units", exc) from None
    return list(nights)


@dataclass(frozen=True)
class ChosenNights:
    """The nights a household's fit uses, and why the others are left out.

    ``nights`` are the chosen nights as read (what :meth:`impctl.fit.NightFit.fit` takes: it
    cuts them at gaps itself); ``cut`` the same cut at gaps (what is classified); ``kept``
    every usable night of the file, ``chosen`` the usable ones fitted; ``missing`` the kinds of
    night without a usable one.
    """

    nights: list
    cut: list
    kept: list
    chosen: list
    skipped: list[tuple[str, str]]
    missing: tuple[str, ...]
    note: str | None = None
    all_nights: list = field(default_factory=list, repr=False)

    def too_little(self, source: str | Path | None = None) -> InputError | None:
        """The refusal when a kind of night is missing (None when both are there)."""
        if not self.missing:
            return None
        from ..imp.plan import EMISSION_LAG_H

        needs = [_NEEDS[k].format(h=MIN_NIGHT_H, lag=EMISSION_LAG_H) for k in self.missing]
        found = ", ".join(f"{n.night_id} ({n.kind})" for n in self.all_nights) or "none"
        why = "; ".join(f"{i}: {r}" for i, r in self.skipped)
        return InputError("too little data to fit: missing " + " and ".join(needs)
                          + f". Nights found: {found}" + (f"; skipped: {why}" if why else ""),
                          source)


def choose_nights(nights: Sequence, max_nights: int = DEFAULT_MAX_NIGHTS) -> ChosenNights:
    """Cut at gaps, keep the usable nights (:func:`impctl.fit.prepare_nights` with the fit's
    defaults), and choose at most ``max_nights``: the most recent, a third of them (at least
    one) constrained when there are enough, the rest normal."""
    from ..imp.gaps import cut_at_gaps
    from ..imp.night import split_owner
    from ..imp.plan import EMISSION_LAG_H
    from .nights.data import prepare_nights

    nights, owner_note = split_owner(list(nights))  # the season model's, not this fit's
    cut, _ = cut_at_gaps(nights, EMISSION_LAG_H)
    kept, _, skipped = prepare_nights(cut, EMISSION_LAG_H, MIN_NIGHT_H, Q_ON_W)
    chosen = _most_recent(kept, max_nights)
    note = None
    chosen_nights, chosen_cut = list(nights), list(cut)
    if len(chosen) < len(kept):
        ids = {n.night_id for n in chosen}
        chosen_nights = [n for n in nights if n.night_id in ids]
        chosen_cut = [n for n in cut if n.night_id in ids]
        note = (f"{len(kept)} usable nights in the file; the fit uses the {len(chosen)} "
                f"most recent ({chosen[0].night_id} … {chosen[-1].night_id}; --max-nights "
                f"{max_nights})")
    if owner_note is not None:
        note = owner_note if note is None else f"{owner_note}; {note}"
    missing = tuple(k for k in ("constrained", "normal") if not any(n.kind == k for n in kept))
    return ChosenNights(chosen_nights, chosen_cut, kept, chosen, skipped, missing, note,
                        list(nights))


def _most_recent(kept: list, max_nights: int) -> list:
    cons = [n for n in kept if n.kind == "constrained"]
    normal = [n for n in kept if n.kind == "normal"]
    n_cons = min(len(cons), max(1, max_nights // 3))
    n_normal = min(len(normal), max_nights - n_cons)
    n_cons = min(len(cons), max_nights - n_normal)
    chosen = cons[len(cons) - n_cons:] + normal[len(normal) - n_normal:]
    return sorted(chosen, key=lambda n: n.start)


@dataclass(frozen=True)
class Classes:
    """A household's classes: per classified parameter its JSON block (``classes``), the
    range the fit searches (``ranges``), the class probabilities the population prior mixes
    (``probabilities``, empty without classifiers), the most probable class labels
    (``labels``, empty without classifiers) and notes for the user."""

    classes: dict[str, dict]
    ranges: dict[str, tuple[float, float]]
    probabilities: dict[str, dict[str, float]]
    labels: dict[str, str]
    notes: list[str]


def household_classes(nights: Sequence, model_dir: str | Path | None = None, *,
                      loaded: tuple[dict, dict] | None = None) -> Classes:
    """Classify the (gap-cut) ``nights`` with the classifiers of ``model_dir`` — or with
    ``loaded`` (models, metadata) a fleet worker keeps — and the search ranges; without usable
    classifiers (or no night at a setpoint they know), the whole prior ranges, said so."""
    from ..classifiers.files.saved import classify_nights, classify_with

    # the classifiers see the IMP nights only, not an auto-cut night on which the setpoint was
    # not held (neither kind: :mod:`impctl.imp.files.held`)
    nights = [n for n in nights if not getattr(n, "not_held", False)]
    try:
        results = (classify_with(list(nights), *loaded) if loaded is not None
                   else classify_nights(list(nights), model_dir))
    except InputError as exc:
        return prior_classes(exc.problem)
    # a parameter the nights do not determine: its prior, no class (ClassResult.source)
    classes = {name: {"range": r.range, "probability": r.probability if r.determined else None,
                      "source": r.source, "calibrated": r.calibrated,
                      "probabilities": dict(r.probabilities),
                      "search_range": r.fit_range}
               for name, r in results.items()}
    left_out = next((r.nights_left_out for r in results.values() if r.nights_left_out), ())
    notes = [f"the classes leave out {len(left_out)} nights run at setpoints the classifiers "
             f"were never trained on: {'; '.join(left_out)} (the fit uses them)"
             ] if left_out else []
    # the fit searches the classes up to SEARCH_LEVEL of probability, not the likeliest alone
    return Classes(classes, {n: c["search_range"] for n, c in classes.items()},
                   {n: c["probabilities"] for n, c in classes.items() if c["probabilities"]},
                   {n: r.label for n, r in results.items()}, notes)


def prior_classes(why: str) -> Classes:
    """No classification (``why``): floor_area, c_f and u_walls over their whole prior ranges."""
    from ..population.ranges import DEFAULT_RANGES

    classes = {name: {"range": (rs[0][0], rs[-1][1]), "probability": None, "source": "prior"}
               for name, rs in DEFAULT_RANGES.items()}
    note = (f"no classification ({why}); floor_area, c_f and u_walls were searched over their "
            "whole prior ranges, so the fit rests on the nights alone")
    return Classes(classes, {n: c["range"] for n, c in classes.items()}, {}, {}, [note])


def fit_refusal(fit, source: str | Path | None = None) -> Refusal | None:
    """The refusal of a finished fit no house gives (a unit or column problem:
    :func:`impctl.imp.plausibility.fit_problem`), or None when it is a house's."""
    from ..imp.plausibility import fit_problem

    eps = ((getattr(fit, "validation_", None) or {}).get("mean") or {}).get("eps_pct")
    why = fit_problem(float(fit.lumped_["hlc"].value), eps)
    return None if why is None else Refusal("implausible fit", InputError(why, source))
