"""What the optional NIGHTS columns let a fit check about its instruments
(:mod:`impctl.imp.files.extras`): the room sensors' and the reference outdoor temperature's
offsets, and the held nights' defrosts whose heat reading did not go negative."""

from __future__ import annotations

import math
from collections.abc import Sequence

from ...imp.night import NightSamples

#: A mean offset of T_out from its reference larger than this [K] on most nights is flagged.
T_OUT_OFFSET_FLAG_K = 1.5
#: Share of the nights whose offset must have the same sign for it to be persistent.
PERSISTENT_SHARE = 0.8


def cross_checks(nights: Sequence[NightSamples]) -> dict:
    """The room sensors' and the outdoor reference's mean offsets over ``nights`` [K]:
    ``t_air_minus_rooms_k`` (the controller's T_air − the room sensors' mean, on the nights
    fitted on the room sensors) and ``t_out_minus_ref_k`` (T_out − its reference), each with
    the nights it covers; the outdoor offset flagged when it exceeds
    :data:`T_OUT_OFFSET_FLAG_K` with the same sign on :data:`PERSISTENT_SHARE` of them."""
    out: dict = {}
    rooms = [n.t_air_offset_k for n in nights if not math.isnan(n.t_air_offset_k)]
    if rooms:
        out["t_air_minus_rooms_k"] = {"mean": sum(rooms) / len(rooms), "nights": len(rooms),
                                      "fitted_on": "t_rooms_c"}
    ref = [n.t_out_offset_k for n in nights if not math.isnan(n.t_out_offset_k)]
    if ref:
        mean = sum(ref) / len(ref)
        same = sum((x > 0) == (mean > 0) for x in ref) / len(ref)
        flagged = abs(mean) > T_OUT_OFFSET_FLAG_K and same >= PERSISTENT_SHARE
        out["t_out_minus_ref_k"] = {"mean": mean, "nights": len(ref), "flagged": flagged}
        if flagged:
            out["t_out_minus_ref_k"]["statement"] = (
                f"the outdoor sensor reads {mean:+.1f} K from its reference on average over "
                f"{len(ref)} nights (more than ±{T_OUT_OFFSET_FLAG_K:g} K, persistent): sun "
                "or a warm wall on the sensor? It shifts ΔT and with it the HLC")
    held = [n for n in nights if n.kind == "normal" and not math.isnan(n.defrost_h)]
    if held:
        hours = sum(n.defrost_h for n in held)
        unread = sum(n.defrost_unread_h for n in held)
        span = sum(n.duration_h for n in held)
        out["defrost"] = {"defrost_h": hours, "unread_h": unread, "nights": len(held),
                          "share": hours / span if span > 0 else 0.0, "flagged": unread > 0}
        if unread > 0:
            out["defrost"]["statement"] = (
                f"the heat reading stayed at or above 0 W in {60 * unread:.0f} of the "
                f"{60 * hours:.0f} min the heat pump defrosted on {len(held)} held nights: it "
                "counts the heat put back after a defrost but not the heat the defrost drew "
                "from the water, so the heat, and with it HLC and C_m, read high (on the "
                "realistic plant, whose meters do this, the defrosts move HLC up by about "
                "4 % on median)")
    return out
