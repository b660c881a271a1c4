"""One IMP night's samples: the common currency of simulated and measured nights."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd

NightKind = Literal["constrained", "normal", "owner"]


@dataclass(frozen=True)
class NightSamples:
    """Samples of one IMP night, whatever their source (simulation, heat pump, CSV).

    Attributes
    ----------
    night_id : str
        Identifier (e.g. ``"2026-01-12"`` or the CSV's ``night`` value).
    kind : {"constrained", "normal", "owner"}
        Heating switched off, or held at ``setpoint_c``; or an owner night: the house as its
        owner runs it, recorded read-only (a local day from noon to noon, rows that are the
        means over [timestamp, timestamp + the row interval)). The fit leaves owner nights
        out (:func:`split_owner`): they are the season model's.
    start : pandas.Timestamp
        Time zone-aware start of the window (time 0 of ``time_s``); of a pre-heat, its first
        sample.
    time_s : ndarray
        Sample times since ``start`` [s], increasing.
    t_air_c, t_out_c : ndarray
        Indoor air and outdoor temperature [°C].
    q_hc_w : ndarray
        Thermal heat output of the heating [W].
    setpoint_c : float
        T_set of the night [°C] (for constrained nights the band centre); NaN if unknown.
    p_house_w : float
        Mean household electricity not used by the heat pump over the night [W] (the
        NIGHTS column ``p_house_w``); NaN if not measured.
    p_house_series_w : ndarray or None
        The same electricity per sample [W] (NaN where a row has none), where the rows carry
        it: the season model reads when in the day the gain falls, the IMP fit the night's
        mean.
    occupants : float
        Mean number of sleepers over the night (the column ``occupants``); NaN if not given.
    night_gain_w : float
        The night gain declared for the night [W] (the column ``night_gain_w``: known, e.g. a
        fleet's per-household declaration); NaN if not declared.
    t_air_offset_k : float
        Mean controller T_air − mean of the room sensors (``t_rooms_c``) [K] on a night whose
        ``t_air_c`` is the room sensors' mean; NaN when the controller's own T_air is used.
    t_out_offset_k : float
        Mean T_out − reference outdoor temperature (``t_out_ref_c``) [K]; NaN without one.
    defrost_h : float
        Hours of the night the heat pump spent defrosting (the column ``defrost``); NaN when
        not logged.
    defrost_unread_h : float
        Of those, the hours whose heat reading stayed at or above 0: the heat a defrost draws
        from the water was not read, the heat put back afterwards was [h]; NaN when not logged.
    not_held : str
        Why an auto-labelled night is neither a held nor a constrained night (heat pulses,
        drift: :mod:`impctl.imp.files.held`); "" for an IMP night. The fit skips it with
        this reason.
    t_flow_c, t_return_c, t_flow_target_c : ndarray or None
        Supply and return water and the heat pump's calculated flow target (its heating
        curve) per sample [°C], NaN where a cell is empty; None when the file has no such
        column. Aligned with ``time_s`` as read (code that cuts ``time_s`` — the fit's gap
        cut, its resampling — does not cut these).
    dhw : ndarray or None
        Share of each sample's time the heat pump charged hot water (0–1; an instant's
        sample 0 or 1), NaN where empty, None without the column; aligned as above.
    defrost_share : ndarray or None
        The ``defrost`` column per sample (share of the row's time the heat pump defrosted,
        0–1; NaN where empty), None without the column; aligned as above.
    label : str
        Why an owner night is not the owner's ordinary night ("owner changed the setpoint:
        …; data missing: …"); "" when it is, and on IMP nights.
    phase : str
        ``"preheat"``: these are an IMP night's pre-heat (the NIGHTS column ``phase``), the
        heat pump raised to T_max before a constrained night or held at the setpoint before a
        normal one; ``night_id`` and ``kind`` are the night's, ``start`` is the first row. Read
        by the season model, left out by the IMP fit (:func:`split_owner`). "" otherwise.
    emitter : str
        The house's emitter as its installer declares it (NIGHTS column ``emitter``:
        "radiators" or "underfloor"), the same on every night of a file; "" when not
        declared (:func:`declared_emitter`).
    """

    night_id: str
    kind: NightKind
    start: pd.Timestamp
    time_s: np.ndarray
    t_air_c: np.ndarray
    t_out_c: np.ndarray
    q_hc_w: np.ndarray
    setpoint_c: float = float("nan")
    p_house_w: float = float("nan")
    p_house_series_w: np.ndarray | None = None
    occupants: float = float("nan")
    night_gain_w: float = float("nan")
    t_air_offset_k: float = float("nan")
    t_out_offset_k: float = float("nan")
    defrost_h: float = float("nan")
    defrost_unread_h: float = float("nan")
    not_held: str = ""
    t_flow_c: np.ndarray | None = None
    t_return_c: np.ndarray | None = None
    t_flow_target_c: np.ndarray | None = None
    dhw: np.ndarray | None = None
    defrost_share: np.ndarray | None = None
    label: str = ""
    phase: str = ""
    emitter: str = ""

    @property
    def duration_h(self) -> float:
        """Covered time [h] from the first to the last sample."""
        return float(self.time_s[-1] - self.time_s[0]) / 3600.0 if len(self.time_s) else 0.0


#: Why the IMP fit, the classifiers and the campaign leave owner nights out (one line, once).
OWNER_NOTE = "owner nights: read by the season model, not by the IMP fit"
#: ... and the constrained nights that reached T_min too soon for them (label SHORT_NIGHT).
SHORT_NOTE = "short constrained nights: read by the season model, not by the IMP fit"


def split_owner(nights: list[NightSamples]) -> tuple[list[NightSamples], str | None]:
    """(the IMP nights, a note when nights were left out): what the fit, the classifiers and
    ``impctl campaign next`` take; the owner nights, the IMP nights' pre-heats (``phase``;
    part of their nights, not nights of their own) and the short constrained nights
    (``label``: :data:`~impctl.imp.protocol.SHORT_NIGHT`) are the season model's."""
    imp = [n for n in nights if n.kind != "owner" and not n.phase and not n.label]
    left = sum(n.kind == "owner" for n in nights)
    short = sum(n.kind != "owner" and not n.phase and bool(n.label) for n in nights)
    notes = [*([f"{OWNER_NOTE} ({left})"] if left else []),
             *([f"{SHORT_NOTE} ({short})"] if short else [])]
    return imp, ("; ".join(notes) or None)


def declared_emitter(nights: list[NightSamples]) -> str | None:
    """The emitter the nights declare (:attr:`NightSamples.emitter`), None where none does.
    Raises InputError when two nights declare different ones (one house, one emitter)."""
    from ..errors import InputError

    kinds = sorted({n.emitter for n in nights if n.emitter})
    if len(kinds) > 1:
        raise InputError(f"the nights declare two emitters ({' and '.join(kinds)}): one house, "
                         "one emitter")
    return kinds[0] if kinds else None
