"""``python -m impctl.plant HOUSE.toml``: check a house file and print its realistic plant.

Bad input: one line on stderr naming the file and key, exit status 2.
"""

from __future__ import annotations

import sys

from ..errors import InputError
from .housefile import load_plant
from .simulation.simulate import PlantCore


def describe(core: PlantCore) -> str:
    """A few lines on the plant of house 0: capacity split, emitter, heat pump."""
    s = {k: float(v[0]) for k, v in core.split.shares.items()}
    return "\n".join([
        f"C_m {core.split.c_m[0] / 1e6:.2f} MJ/K: mass {s['mass']:.1%}, air {s['air']:.1%}, "
        f"furniture {s['furniture']:.1%}, emitter {s['emitter']:.1%}",
        f"HLC {core.hlc[0]:.1f} W/K; emitter K {core.k_w[0]:.1f} W/K^n, n {core.exponent[0]:.2f}, "
        f"C_em {core.c_em[0] / 1e3:.0f} kJ/K",
        f"heat pump nominal {core.nominal_w[0]:.0f} W, minimum "
        f"{core.controller.p_min_frac[0] * core.nominal_w[0]:.0f} W",
    ])


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m impctl.plant HOUSE.toml", file=sys.stderr)
        return 2
    try:
        house, params = load_plant(args[0])
    except InputError as exc:
        print(exc, file=sys.stderr)
        return 2
    print(describe(PlantCore(house, params)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
