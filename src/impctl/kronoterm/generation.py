"""Which register set does the controller have? Several pieces of evidence, cross-checked.

A single plausible probe is not enough (issue 15): an extended controller at night has its
compressor idle, COP 0, perhaps no loop-1 mixing sensor (2130 = −600) and SCOP in the
three-decimal encoding (5413 = 5.413); a TT3000/WPG may answer undocumented registers with
numbers (2130 low, 2329 = 1234 W). So each check says *extended*, *contradiction* or nothing:

* extended-only registers answering exception 2 (illegal address): compact;
* 2130 (loop-1 water) against 2104/2101 (supply/return): a real loop-1 temperature lies near
  them; −600 (sensor not fitted) says nothing;
* 2329 (thermal W) against 2129 (electrical W) × COP and the compressor bit (2318): with the
  compressor off both are ~0, with it on their ratio is a COP of 1…8;
* the lifetime energy counters (2361/2362 electrical kWh, 2363/2364 thermal 0.1 kWh): their
  ratio is a seasonal COP of 1…8;
* COP/SCOP (2371/2372): the scale (×0.01 or ×0.001, both exist in the field) is the one that
  gives a plausible value, preferring the one closest to the counters' ratio.

Extended evidence without contradiction → extended; contradictions without extended evidence
→ compact (undocumented registers that answer nonsense); both, or neither → *doubt*: the
client reads only the compact set and refuses experiments that need Q_HC from 2329, with one
line naming the evidence and the configuration that settles it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..modbus import ModbusDeviceError, ModbusLink, to_int16, uint32
from .registers import Generation

#: Plausible coefficient of performance of a running heat pump.
COP_RANGE = (1.0, 8.0)
#: Scales of COP/SCOP seen in the field (Favio25 v1.6.9 / v1.7.2).
COP_SCALES = (0.01, 0.001)
_PROBED = (2101, 2104, 2129, 2130, 2318, 2327, 2329, 2361, 2362, 2363, 2364, 2371, 2372)
_EXTENDED_ONLY = (2129, 2130, 2318, 2327, 2329, 2361, 2363, 2371, 2372)


@dataclass(frozen=True)
class GenerationReport:
    """Result of :meth:`HeatPumpClient.detect_generation`.

    Attributes
    ----------
    generation : Generation
        The register set the client uses (compact while in doubt).
    evidence : dict
        Check → finding, e.g. ``"2130 vs 2104": "−600: loop-1 sensor not fitted (no
        evidence)"``.
    doubt : str or None
        Why the evidence does not settle the question (IMP nights needing Q_HC from 2329 are
        refused then), or None.
    cop_scale, scop_scale : float or None
        Scale chosen for 2371/2372 by plausibility (None: no plausible value now).
    source : "configured" or "detected"
    """

    generation: Generation
    evidence: dict[str, str]
    doubt: str | None = None
    cop_scale: float | None = None
    scop_scale: float | None = None
    source: str = "detected"

    def as_dict(self) -> dict:
        """JSON-friendly form (for ``impctl status``)."""
        return {"generation": self.generation.value, "source": self.source,
                "doubt": self.doubt, "evidence": dict(self.evidence),
                "cop_scale": self.cop_scale, "scop_scale": self.scop_scale}


@dataclass
class _Findings:
    extended: list[str] = field(default_factory=list)
    against: list[str] = field(default_factory=list)
    evidence: dict[str, str] = field(default_factory=dict)

    def add(self, check: str, finding: str, verdict: str | None) -> None:
        self.evidence[check] = finding
        if verdict == "extended":
            self.extended.append(check)
        elif verdict == "against":
            self.against.append(check)


def plausible_scale(raw: int, expected: float | None = None) -> float | None:
    """The COP/SCOP scale that makes ``raw`` a plausible COP (closest to ``expected``)."""
    fits = [s for s in COP_SCALES if COP_RANGE[0] <= raw * s <= COP_RANGE[1] * 1.25]
    if not fits:
        return None
    if expected is None:
        return fits[0]
    return min(fits, key=lambda s: abs(raw * s - expected))


async def _probe(link: ModbusLink) -> dict[int, int | None]:
    """Raw signed words of the probed registers (unsigned for counters); None = exception 2."""
    words: dict[int, int | None] = {}
    for ma in _PROBED:
        try:
            word = (await link.read(ma - 1, 1))[0]
        except ModbusDeviceError as exc:
            if exc.exception_code != 2:  # busy/failing is no evidence of a missing register
                raise
            words[ma] = None
            continue
        words[ma] = word if ma in (2318, 2361, 2362, 2363, 2364) else to_int16(word)
    return words


async def detect(link: ModbusLink) -> GenerationReport:
    """Probe and cross-check (see the module docstring).

    Raises
    ------
    ModbusDeviceError
        An exception other than 2 on every try (e.g. busy): nothing can be concluded.
    ModbusLinkError
        No answer.
    """
    w = await _probe(link)
    found = _Findings()
    absent = [ma for ma in _EXTENDED_ONLY if w[ma] is None]
    if len(absent) == len(_EXTENDED_ONLY):
        found.add("extended registers", "all answer exception 2 (illegal address)", None)
        return GenerationReport(Generation.COMPACT, found.evidence)
    if absent:
        found.add("extended registers", f"{absent} answer exception 2", "against")
    _loop1(w, found)
    ratio = _counters(w, found)
    _power(w, found)
    cop_scale = scop_scale = None
    if w[2372] is not None and w[2372] > 0:
        scop_scale = plausible_scale(w[2372], ratio)
        found.add("2372 SCOP", f"raw {w[2372]}" + (
            f" → {w[2372] * scop_scale:.3g} at ×{scop_scale:g}" if scop_scale
            else ": implausible at ×0.01 and ×0.001"), "extended" if scop_scale else "against")
    if w[2371] is not None and w[2371] > 0:
        cop_scale = plausible_scale(w[2371], ratio)
        found.add("2371 COP", f"raw {w[2371]}" + (
            f" → {w[2371] * cop_scale:.3g} at ×{cop_scale:g}" if cop_scale
            else ": implausible"), None if cop_scale else "against")
    doubt = None
    if found.extended and not found.against:
        generation = Generation.EXTENDED
    elif found.against and not found.extended:
        generation = Generation.COMPACT
    else:
        generation = Generation.COMPACT
        why = ("the evidence disagrees: extended by " + ", ".join(found.extended)
               + "; not by " + ", ".join(found.against)) if found.extended else (
            "no register gives evidence either way")
        doubt = (f"controller generation uncertain ({why}); set generation = \"extended\" or "
                 "\"compact\" in [heatpump] (see impctl status for the evidence)")
    return GenerationReport(generation, found.evidence, doubt, cop_scale, scop_scale)


def _loop1(w: dict[int, int | None], found: _Findings) -> None:
    raw = w[2130]
    supply, ret = w[2104], w[2101]
    if raw is None:
        return
    if raw <= -500:
        found.add("2130 vs 2104", f"raw {raw}: loop-1 sensor not fitted (no evidence)", None)
        return
    temps = [t / 10 for t in (supply, ret) if t is not None and t > -500]
    if not temps:
        found.add("2130 vs 2104", "no supply/return temperature to compare", None)
        return
    low, high = min(temps) - 8.0, max(temps) + 8.0
    value = raw / 10
    agrees = low <= value <= high
    found.add("2130 vs 2104", f"loop-1 water {value:.1f} °C, supply/return "
              f"{'/'.join(f'{t:.1f}' for t in temps)} °C: "
              f"{'consistent' if agrees else 'inconsistent'}",
              "extended" if agrees else "against")


def _counters(w: dict[int, int | None], found: _Findings) -> float | None:
    if any(w[ma] is None for ma in (2361, 2362, 2363, 2364)):
        return None
    e_el = uint32([w[2361], w[2362]])
    e_th = uint32([w[2363], w[2364]]) * 0.1
    if e_el == 0 and e_th == 0:
        found.add("energy counters", "both 0 (no evidence)", None)
        return None
    ratio = e_th / e_el if e_el else float("inf")
    ok = COP_RANGE[0] <= ratio <= COP_RANGE[1]
    found.add("energy counters", f"thermal {e_th:.1f} kWh / electrical {e_el} kWh = "
              f"{ratio:.3g}: {'plausible' if ok else 'implausible'} seasonal COP",
              "extended" if ok else "against")
    return ratio if ok else None


def _power(w: dict[int, int | None], found: _Findings) -> None:
    q, p, bits = w[2329], w[2129], w[2318]
    if q is None or p is None or bits is None:
        return
    running = bool(bits & 0b11)
    check = "2329 vs 2129 × COP"
    if not running:
        if q <= 50 and p <= 50:
            found.add(check, f"compressor off, thermal {q} W, electrical {p} W: consistent "
                      "(no evidence)", None)
        else:
            found.add(check, f"compressor off but thermal {q} W, electrical {p} W: "
                      "inconsistent", "against")
        return
    ratio = q / p if p > 0 else float("inf")
    ok = COP_RANGE[0] <= ratio <= COP_RANGE[1]
    found.add(check, f"compressor on, thermal {q} W / electrical {p} W = {ratio:.3g}: "
              f"{'plausible' if ok else 'implausible'} COP", "extended" if ok else "against")
