"""A heating curve set as flow temperatures at two outdoor temperatures (a Kronoterm's loop-1
curve points), and how the heat pump turns it into the water temperature it regulates.

The line through (θ_a, F_a) and (θ_b, F_b) [°C] gives the flow (supply) temperature the heat
pump aims at for the sensed outdoor temperature θ_e, extrapolated beyond the points. It is set
for a room setpoint θ_ref; another setpoint θ_set moves it as a matched curve moves, along and
up: F(θ_e; θ_set) = line(θ_e − Δ) + Δ with Δ = θ_set − θ_ref [own choice: the Kronoterm
documents neither the shape between the points nor how the setpoint shifts the curve]. The
room influence k·(θ_set − θ_air,sensed) is added as on the built-in curve.

The plant's control regulates the emitter node (the radiators' mean water, the screed), whose
steady output K·d^n, d = node − θ_set, runs the water above the node by P/G_pipe and the flow
above the mean water by P/(2·ṁc). The node temperature whose steady flow is F solves
d + r·K·dⁿ = F − θ_set with r = 1/G_pipe + 1/(2·ṁc) [K/W] (:func:`node_for_flow`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: Outdoor temperatures of the two curve points [°C]: Kronoterm's "first point (−15)" and
#: "second point (+15)" of a heating loop (registers 2309/2314, heating mode).
CURVE_POINTS_T_OUT_C = (-15.0, 15.0)
#: Newton steps of :func:`node_for_flow` (converges from above in a few; 6 is ample).
_NEWTON_STEPS = 6


def curve_flow_c(flow_a_c: Array, flow_b_c: Array, setpoint_ref_c: Array, setpoint_c: Array,
                 t_out_c: Array, points_c: tuple[float, float] = CURVE_POINTS_T_OUT_C) -> Array:
    """Flow temperature of the two-point curve at outdoor ``t_out_c`` for ``setpoint_c`` [°C]
    (module docstring)."""
    a, b = points_c
    shift = setpoint_c - setpoint_ref_c
    slope = (flow_b_c - flow_a_c) / (b - a)
    return flow_a_c + slope * (t_out_c - shift - a) + shift


def node_for_flow(flow_c: Array, setpoint_c: Array, k_w: Array, exponent: Array,
                  lag_k_per_w: Array) -> Array:
    """Emitter node temperature [°C] whose steady output puts the flow at ``flow_c`` [°C].

    Solves d + r·K·dⁿ = F − θ_set for d ≥ 0 by Newton steps from an upper bound (the left side
    is convex and increasing, so the steps fall monotonically onto the root); a flow at or
    below the setpoint delivers nothing and is the node temperature itself.
    """
    excess = flow_c - setpoint_c
    pos = np.maximum(excess, 0.0)
    rk = lag_k_per_w * k_w
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(rk > 0, (pos / np.where(rk > 0, rk, 1.0)) ** (1.0 / exponent), pos)
    d = np.minimum(pos, bound)
    for _ in range(_NEWTON_STEPS):
        dn1 = np.maximum(d, 1e-9) ** (exponent - 1.0)
        g = d + rk * dn1 * d - pos
        d = np.maximum(d - g / (1.0 + rk * exponent * dn1), 0.0)
    return np.where(excess > 0, setpoint_c + d, flow_c)


def flow_for_node(node_c: Array, setpoint_c: Array, k_w: Array, exponent: Array,
                  lag_k_per_w: Array) -> Array:
    """Steady flow temperature [°C] of an emitter node held at ``node_c`` (the inverse of
    :func:`node_for_flow`)."""
    d = np.maximum(node_c - setpoint_c, 0.0)
    return node_c + lag_k_per_w * k_w * d ** exponent
