"""Is the night's heat output (Q_HC) believable? Cross-checks against electrical power.

Q_HC is what the identification integrates; a register that does not exist on the controller
(a TT3000 answering 2329 with 1234 W), a stuck value or a misread scale gives a night whose fit
is wrong without any error. Every night's samples are checked (issue 15):

* **range**: Q_HC between 0 W and the installation's capacity (default 25 kW, larger than any
  residential Kronoterm unit); defrost samples may be negative and are skipped;
* **thermal against electrical × COP**: with the compressor running (electrical ≥ 100 W) the
  ratio Q_HC / P_el is a COP of 0.8…8; with it off (electrical ≤ 50 W) Q_HC stays ≤ 500 W
  (only the water's run-on) — more than 20 % of samples outside this fail the night;
* **stuck**: the same non-zero Q_HC for 2 h or more while electrical power moved by more
  than a quarter of its mean (50 W at least) or the supply temperature by more than 3 K (a
  compressor held at its cap keeps a steady output with only slowly drifting COP).

Samples without electrical power (a compact controller with a heat meter) skip the ratio check.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..store import Sample

#: Plausible ratio of thermal to electrical power while the compressor runs.
COP_BAND = (0.8, 8.0)
#: Electrical power above which the compressor counts as running / below which as off [W].
RUNNING_W, OFF_W = 100.0, 50.0
#: Thermal power allowed while the compressor is off (run-on of the water) [W].
OFF_Q_MAX_W = 500.0
#: Default heat capacity of a residential installation [W].
CAPACITY_W = 25_000.0
#: Share of checkable samples that may fail the ratio check.
MAX_BAD_SHARE = 0.20
#: Shortest stuck run that fails the night [s].
STUCK_S = 2 * 3600.0


def heat_output_problems(samples: Sequence[Sample], capacity_w: float = CAPACITY_W
                         ) -> list[str]:
    """Reasons the night's Q_HC cannot be trusted (empty when it passes).

    Parameters
    ----------
    samples : sequence of Sample
        The night's samples in time order (Q_HC and P_el in W, T_supply in °C).
    capacity_w : float
        Largest heat output the installation can deliver [W].
    """
    rows = [s for s in samples if s.q_hc_w is not None and not s.defrost]
    if not rows:
        return []
    problems = []
    out_of_range = [s for s in rows if not 0.0 <= s.q_hc_w <= capacity_w]
    if out_of_range:
        worst = max(out_of_range, key=lambda s: abs(s.q_hc_w)).q_hc_w
        problems.append(f"Q_HC outside 0…{capacity_w:.0f} W in {len(out_of_range)} sample(s) "
                        f"(e.g. {worst:.0f} W)")
    checked = bad = 0
    for s in rows:
        if s.p_el_w is None:
            continue
        if s.p_el_w >= RUNNING_W:
            checked += 1
            ratio = s.q_hc_w / s.p_el_w
            bad += not COP_BAND[0] <= ratio <= COP_BAND[1]
        elif s.p_el_w <= OFF_W:
            checked += 1
            bad += s.q_hc_w > OFF_Q_MAX_W
    if checked and bad / checked > MAX_BAD_SHARE:
        problems.append(f"Q_HC disagrees with electrical power × COP {COP_BAND[0]:g}…"
                        f"{COP_BAND[1]:g} and the compressor state in {bad / checked:.0%} of "
                        "samples")
    stuck = _stuck(rows)
    if stuck:
        problems.append(stuck)
    return problems


def _stuck(rows: Sequence[Sample]) -> str | None:
    start = 0
    for i in range(1, len(rows) + 1):
        if i < len(rows) and rows[i].q_hc_w == rows[start].q_hc_w:
            continue
        run = rows[start:i]
        span = (run[-1].ts - run[0].ts).total_seconds()
        if run[0].q_hc_w and span >= STUCK_S and _moved(run):
            return (f"Q_HC stuck at {run[0].q_hc_w:.0f} W for {span / 3600:.1f} h while the "
                    "heat pump's other readings changed")
        start = i
    return None


def _moved(run: Sequence[Sample]) -> bool:
    def spread(values: list[float]) -> float:
        return max(values) - min(values) if values else 0.0

    p_el = [s.p_el_w for s in run if s.p_el_w is not None]
    supply = [s.t_supply_c for s in run if s.t_supply_c is not None]
    moved_el = bool(p_el) and spread(p_el) > max(50.0, 0.25 * sum(p_el) / len(p_el))
    return moved_el or spread(supply) > 3.0
