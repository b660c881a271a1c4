"""The IMP fit of ``impctl fit`` in a forked worker that loads torch while the command's own
process reads and checks the NIGHTS file.

torch and the fit's modules take about as long to load as the fit takes to run, and reading
the file needs none of them. So the command forks the worker before it reads: the worker loads
torch, then waits for the nights; the command reads, checks and classifies them (a refused
file is refused without waiting for torch, which the command's own process never loads), sends
them and gets back what it prints and writes — the JSON summary and, for ``--plot``, the
curves the figure draws. The fit is the same function in either process: the worker, or the
command itself when there is no fork, when torch is loaded already (nothing to overlap) or when
the worker died.
"""

from __future__ import annotations

import multiprocessing
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

from ...errors import InputError


@dataclass(frozen=True)
class FitRequest:
    """What the fit needs from the command: the chosen nights, the classes and the options."""

    nights: list
    ranges: dict[str, tuple[float, float]]
    probabilities: dict[str, dict[str, float]]
    classes: dict[str, dict]
    notes: list[str]
    estimator_params: dict
    source: str
    plot: bool = False


@dataclass(frozen=True)
class FitOutcome:
    """The fit's JSON summary (:func:`impctl.fit.result.report.fit_to_dict`) and, when the
    request asked for a plot, the figure's curves and title (:func:`impctl.fit.result.plot.
    figure_of`)."""

    summary: dict
    figure: tuple[list[dict], str] | None = None


def fit_request(request: FitRequest) -> FitOutcome:
    """The IMP fit of ``request``, here. Raises the refusal (:class:`InputError`) of a file no
    night of which is usable or whose fit no house gives."""
    from ...fit.estimator import NightFit
    from ...fit.household import fit_refusal
    from ...fit.prior import with_class_probabilities
    from ...fit.result.plot import figure_of
    from ...fit.result.report import fit_to_dict

    estimator = NightFit(**request.estimator_params)
    # the population prior mixes the classes by the classifiers' probabilities
    estimator.prior = with_class_probabilities(estimator.prior, request.probabilities)
    estimator.fit(request.nights, request.ranges)
    # A fit no house gives is a unit or column problem: refuse it, write nothing.
    refusal = fit_refusal(estimator, request.source)
    if refusal is not None:
        raise refusal
    return FitOutcome(fit_to_dict(estimator, request.classes, request.notes),
                      figure_of(estimator) if request.plot else None)


class FitWorker:
    """The forked worker (:func:`_work`) as a context: on leaving it — the fit done, a refusal
    raised or any error — a worker still running is stopped."""

    def __init__(self) -> None:
        self._conn = self._proc = None
        if "torch" in sys.modules:  # loaded already (a test's process): nothing to overlap
            return
        try:
            ctx = multiprocessing.get_context("fork")
        except ValueError:  # no fork on this platform
            return
        parent, child = ctx.Pipe()
        # daemon: the worker dies with the command (Ctrl-C, an error while reading)
        self._proc = ctx.Process(target=_work, args=(child,), daemon=True)
        self._proc.start()
        child.close()
        self._conn = parent

    def __enter__(self) -> FitWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def fit(self, request: FitRequest) -> FitOutcome:
        """:func:`fit_request` in the worker, or here when there is none or it died."""
        reply = None
        if self._conn is not None:
            try:
                self._conn.send(request)
                reply = self._conn.recv()
            except (EOFError, OSError):  # the worker died: fitted here below
                pass
            self.stop(replied=reply is not None)
        if reply is None:
            return fit_request(request)
        if reply[0] == "refused":
            raise InputError(*reply[1:])
        return reply[1]

    def stop(self, replied: bool = False) -> None:
        """Stop the worker: wait for it to exit once it has ``replied``, else kill it (a
        refused file is not kept waiting for torch to load)."""
        if self._proc is None:
            return
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if not replied and self._proc.exitcode is None:
            self._proc.kill()
        self._proc.join()
        self._proc = None


def _work(conn) -> None:
    """The worker: load torch and the fit, wait for a request, reply with the outcome, a
    refusal, or None when anything else went wrong (the command then fits again itself and
    shows the error)."""
    # Ctrl-C reaches the whole process group: the command stops the worker itself
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from ...fit import estimator, household, prior  # noqa: F401 - loaded while the file is read
        from ...fit.result import plot, report  # noqa: F401

        request = conn.recv()
    except (EOFError, OSError):  # the command is done without a fit
        return
    except Exception:  # noqa: BLE001 - the command loads it again and sees the error itself
        request = None
    try:
        reply = None if request is None else ("fitted", fit_request(request))
    except InputError as exc:
        reply = ("refused", exc.problem, exc.source, exc.place)
    except Exception:  # noqa: BLE001 - as above
        reply = None
    try:
        conn.send(reply)
    except (OSError, ValueError):  # the command stopped waiting
        pass
    except Exception:  # noqa: BLE001 - a reply that does not pickle: the command fits itself
        conn.send(None)
    finally:
        conn.close()


def draw_outcome(outcome: FitOutcome, path: Path) -> None:
    """Draw ``outcome``'s figure to ``path`` (:func:`impctl.fit.result.plot.save_figure`)."""
    from ...fit.result.plot import save_figure

    assert outcome.figure is not None, "the request did not ask for a plot"
    save_figure(*outcome.figure, path)
