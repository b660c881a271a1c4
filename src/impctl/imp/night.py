"""One IMP night's samples: the common currency of simulated and measured nights."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd

NightKind = Literal["constrained", "normal"]


@dataclass(frozen=True)
class NightSamples:
    """Samples of one IMP night, whatever their source (simulation, heat pump, CSV).

    Attributes
    ----------
    night_id : str
        Identifier (e.g. ``"2026-01-12"`` or the CSV's ``night`` value).
    kind : {"constrained", "normal"}
        Heating switched off, or held at ``setpoint_c``.
    start : pandas.Timestamp
        Time zone-aware start of the window (time 0 of ``time_s``).
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
        drift: :mod:`impctl.imp.held`); "" for an IMP night. The fit skips it with this reason.
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
    occupants: float = float("nan")
    night_gain_w: float = float("nan")
    t_air_offset_k: float = float("nan")
    t_out_offset_k: float = float("nan")
    defrost_h: float = float("nan")
    defrost_unread_h: float = float("nan")
    not_held: str = ""

    @property
    def duration_h(self) -> float:
        """Covered time [h] from the first to the last sample."""
        return float(self.time_s[-1] - self.time_s[0]) / 3600.0 if len(self.time_s) else 0.0
