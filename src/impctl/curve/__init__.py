"""The heating curve this house needs, measured, and what lowering the running one saves.

In pipeline order after :mod:`impctl.fit`, beside :mod:`impctl.flex`; rooms named after the
physics they hold:

* :mod:`.data` — what it is worked out from: :mod:`.data.rows`, the NIGHTS rows with the
  flow, return and target temperatures, hot water, defrost and electricity a gateway records
  on held and owner nights; :mod:`.data.blocks`, steady blocks of those rows (the night, the
  two halves of the day); :mod:`.data.synth`, such rows simulated for tests and benches;
* :mod:`.emitter` — the emitter measured: Q = K·ΔT_wⁿ with intervals;
* :mod:`.need` — the heat need (the fit's HLC, the heat the blocks show) and the flow
  temperature it takes, at its upper bound plus a stated margin; the recommended line;
* :mod:`.running` — the curve the heat pump runs, from its own flow target;
* :mod:`.cop` — its efficiency against the flow temperature, fitted or assumed;
* :mod:`.savings` — the winter's electricity at both curves;
* :mod:`.result` — the JSON and the owner's words; :mod:`.plot` — the figure;
* :mod:`.analysis` — all of it for one house (:func:`analyse`).
"""

from .analysis import DEFAULT_MARGIN_K, analyse
from .data.rows import read_rows
from .result import SCHEMA, CurveResult

__all__ = ["DEFAULT_MARGIN_K", "SCHEMA", "CurveResult", "analyse", "read_rows"]
