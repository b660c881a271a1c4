"""The class of one parameter, as the classifiers report it (:class:`ClassResult`), and how a
parameter the nights do not determine is reported (:data:`NOT_DETERMINED`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: How a parameter the nights do not determine is reported (``ClassResult.source``).
NOT_DETERMINED = "prior: not determined by the nights"


@dataclass(frozen=True)
class ClassResult:
    """The class of one parameter.

    Attributes
    ----------
    parameter : str
    label : str
        Most probable range label, e.g. ``"200-300"``; when the parameter is not determined,
        the label of the whole prior range (no class is reported).
    range : (float, float)
        That range, in the parameter's unit.
    probability : float
        Its probability (0–1): calibrated (the forest's votes mapped to class frequencies of
        households it never saw) when ``calibrated``, else the share of votes; 1 for the
        whole prior range of a parameter not determined.
    probabilities : dict
        Every range label → probability; the training prior (class frequencies) when the
        parameter is not determined.
    determined : bool
        False when the classifier's classes do not beat the majority class on held-out
        training households (:data:`impctl.classifiers.estimator.MIN_MARGIN`): the nights do
        not determine the parameter, and ``probabilities`` are the prior.
    """

    parameter: str
    label: str
    range: tuple[float, float]
    probability: float
    probabilities: dict[str, float] = field(default_factory=dict)
    calibrated: bool = False
    nights_left_out: tuple[str, ...] = ()
    search_range: tuple[float, float] | None = None
    determined: bool = True

    @property
    def source(self) -> str:
        """Where the class comes from: ``"classifier"``, or :data:`NOT_DETERMINED`."""
        return "classifier" if self.determined else NOT_DETERMINED

    @property
    def probability_kind(self) -> str:
        """What ``probabilities`` are: ``"calibrated probability"``, ``"vote share"`` (a
        model too small to calibrate) or ``"prior class frequency"``."""
        if not self.determined:
            return "prior class frequency"
        return "calibrated probability" if self.calibrated else "vote share"

    @property
    def fit_range(self) -> tuple[float, float]:
        """The range the fit searches, in the parameter's unit: the hull of the most probable
        classes up to :data:`~impctl.classifiers.files.saved.SEARCH_LEVEL` of probability
        (:func:`~impctl.classifiers.files.saved.credible_hull`); the class's
        own range when no probabilities were kept."""
        return self.search_range or self.range

    def probability_text(self) -> str:
        """One line for a table: ``"72 % (calibrated probability)"``, or for a parameter the
        nights do not determine ``"not determined by the nights; prior 0.8-1.65 69 %,
        1.65-3.7 31 %"``."""
        if not self.determined:
            prior = ", ".join(f"{k} {100 * p:.0f} %" for k, p in self.probabilities.items())
            return f"not determined by the nights; prior {prior}"
        return f"{100 * self.probability:.0f} % ({self.probability_kind})"

    def as_dict(self) -> dict[str, Any]:
        """JSON form: ``{"range": [lo, hi], "label": …, "probability": p, "probabilities": …,
        "search_range": [lo, hi]}``
        (and ``"nights_left_out"``: the nights not classified because they ran at a setpoint
        the classifiers' population never ran, when there are any)."""
        out = {"range": list(self.range), "label": self.label,
               "probability": self.probability, "probabilities": dict(self.probabilities),
               "calibrated": self.calibrated, "determined": self.determined,
               "source": self.source, "probability_kind": self.probability_kind,
               "search_range": list(self.fit_range)}
        if self.nights_left_out:
            out["nights_left_out"] = list(self.nights_left_out)
        return out
