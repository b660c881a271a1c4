"""Saved range classifiers: where they live, how they are stored, and classifying measured nights.

A model directory holds one ``<parameter>.joblib`` per classified parameter (a fitted
:class:`~.estimator.RangeClassifier`) and ``models.json`` with their metadata: format, ranges and
labels, campaign and night feature names, the emitter lag, the training seed and size, package
versions and the evaluation report. :func:`load_models` refuses, with one line saying what to do,
a directory without models, another format, other features, or another scikit-learn version.
``forests.npz`` (:mod:`.compact`, when the export reproduced scikit-learn) holds the same forests
as arrays: :func:`classify_nights` uses it when present, so classifying needs no scikit-learn.
"""

from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd

from ...atomic import replacing
from ...errors import InputError
from ...imp import NIGHT_FEATURE_NAMES, NightSamples, night_features
from ...population.dataset import package_versions
from ...population.ranges import labels_of, range_label
from ..campaign import CAMPAIGN_FEATURE_NAMES, campaign_features
from ..result import ClassResult
from .compact import COMPACT_FILE, load_compact, save_compact

#: 2: cross-validated calibration, the training prior and the determination verdict in the
#: models (older model directories are refused and retrained).
MODEL_FORMAT = 2
METADATA_FILE = "models.json"
RETRAIN = "run `impctl train` to train them"
#: The fit searches the hull of the most probable classes whose probabilities add up to this:
#: a calibrated 72 % class is wrong one time in four, and a box without the house in it holds
#: the fit at its edge with an interval that misses (measured: C_m coverage 88 % with the most
#: probable class's box on the bench's realistic houses; decision record 0012).
SEARCH_LEVEL = 0.95


def default_model_dir() -> Path:
    """Directory of the trained models: ``$IMPCTL_MODEL_DIR``, else the per-user data directory.

    The per-user default is ``platformdirs.user_data_path("impctl") / "models"`` (e.g.
    ``~/.local/share/impctl/models`` on Linux). The daemon, running as a service user, points
    ``IMPCTL_MODEL_DIR`` (or ``--model-dir``) at its state directory.
    """
    env = os.environ.get("IMPCTL_MODEL_DIR")
    if env:
        return Path(env)
    import platformdirs

    return platformdirs.user_data_path("impctl", appauthor=False) / "models"


def save_models(models: dict, directory: str | Path, *, seed: int, n_households: int,
                emission_lag_h: float, report: dict | None = None,
                dataset_manifest: dict | None = None) -> Path:
    """Write ``models`` (parameter → fitted RangeClassifier) and ``models.json`` into ``directory``.

    Files are written under temporary names and renamed, so a reader never sees half a model.
    Raises ValueError for a model trained on a subset of the campaign features (a bench's
    ``TrainConfig(features=...)``): classification computes them all.
    """
    import joblib

    for name, model in models.items():
        if list(getattr(model, "feature_names_in_", CAMPAIGN_FEATURE_NAMES)) != list(
                CAMPAIGN_FEATURE_NAMES):
            raise ValueError(f"model {name!r} was not trained on all campaign features")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    params = {}
    for name, model in models.items():
        target = directory / f"{name}.joblib"
        with replacing(target) as tmp:
            joblib.dump(model, tmp, compress=3)
        params[name] = {"file": target.name, "ranges": [list(r) for r in model.ranges],
                        "labels": labels_of(tuple(model.ranges)),
                        "calibration": model.calibration if model.calibrated_ else None,
                        "determined": bool(getattr(model, "determined_", True)),
                        "prior": [float(p) for p in getattr(model, "prior_", [])],
                        "cv_accuracy": _number(getattr(model, "cv_accuracy_", None)),
                        "cv_majority": _number(getattr(model, "cv_majority_", None)),
                        "cv_margin_low": _number(getattr(model, "cv_margin_low_", None))}
    meta = {
        "format": MODEL_FORMAT,
        "parameters": params,
        "campaign_features": list(CAMPAIGN_FEATURE_NAMES),
        "night_features": list(NIGHT_FEATURE_NAMES),
        "emission_lag_h": float(emission_lag_h),
        "seed": int(seed),
        "n_households": int(n_households),
        "versions": package_versions(),
        "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "report": report or {},
        "dataset": dataset_manifest or {},
    }
    # The forests as plain arrays too, checked against scikit-learn (.compact): classifying
    # from them needs neither scikit-learn nor unpickling.
    if save_compact(models, directory) is not None:
        meta["compact"] = COMPACT_FILE
    with replacing(directory / METADATA_FILE) as tmp:
        tmp.write_text(json.dumps(meta, indent=2) + "\n")
    return directory


def _number(value) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


def add_compact(model_dir: str | Path) -> bool:
    """Write the compact forests (:mod:`.compact`) for models saved without them (older
    models); True when the directory has them afterwards."""
    directory = Path(model_dir)
    models, meta = load_models(directory)
    if save_compact(models, directory) is None:
        return False
    meta["compact"] = COMPACT_FILE
    with replacing(directory / METADATA_FILE) as tmp:
        tmp.write_text(json.dumps(meta, indent=2) + "\n")
    return True


def _minor(version: str) -> str:
    return ".".join(version.split(".")[:2])


def _metadata(directory: Path) -> dict:
    """``models.json`` of ``directory``, checked: format and feature names."""
    meta_path = directory / METADATA_FILE
    if not meta_path.is_file():
        raise InputError(f"no trained models here; {RETRAIN}", directory)
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"unreadable model metadata ({exc}); {RETRAIN} again", meta_path) from None
    if not isinstance(meta, dict) or meta.get("format") != MODEL_FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise InputError(f"model format {got!r}, this impctl reads {MODEL_FORMAT}; {RETRAIN} "
                         "again", meta_path)
    if meta.get("campaign_features") != list(CAMPAIGN_FEATURE_NAMES) or \
            meta.get("night_features") != list(NIGHT_FEATURE_NAMES):
        raise InputError("models were trained on other features than this impctl computes; "
                         f"{RETRAIN} again", meta_path)
    return meta


def load_models(model_dir: str | Path | None = None) -> tuple[dict, dict]:
    """Load the classifiers of ``model_dir`` (default :func:`default_model_dir`).

    Returns
    -------
    models : dict parameter → RangeClassifier
    metadata : dict (the content of ``models.json``)

    Raises
    ------
    InputError
        No models, unreadable metadata, another model format, other features, another
        scikit-learn version, a missing or foreign model file.
    """
    directory = Path(model_dir) if model_dir is not None else default_model_dir()
    meta = _metadata(directory)
    meta_path = directory / METADATA_FILE
    import sklearn

    saved = str(meta.get("versions", {}).get("scikit-learn", "unknown"))
    if _minor(saved) != _minor(sklearn.__version__):
        raise InputError(f"models were trained with scikit-learn {saved}, this is "
                         f"{sklearn.__version__}; {RETRAIN} again", meta_path)
    import joblib

    from ..estimator import RangeClassifier

    models = {}
    for name, info in meta.get("parameters", {}).items():
        path = directory / str(info.get("file", ""))
        try:
            model = joblib.load(path)
        except Exception as exc:  # joblib/pickle raise many types for damaged files
            raise InputError(f"cannot load the {name} model ({type(exc).__name__}); {RETRAIN} "
                             "again", path) from None
        ranges = [list(r) for r in getattr(model, "ranges", ())]
        if not isinstance(model, RangeClassifier) or ranges != info.get("ranges"):
            raise InputError(f"not the {name} model models.json describes; {RETRAIN} again",
                             path)
        models[name] = model
    if not models:
        raise InputError(f"models.json lists no models; {RETRAIN}", meta_path)
    return models, meta


def classify_nights(nights: list[NightSamples], model_dir: str | Path | None = None
                    ) -> dict[str, ClassResult]:
    """Put a house into parameter ranges from its measured (or simulated) IMP nights.

    All nights are combined into one campaign row (:mod:`impctl.classifiers.campaign`) before the
    forests classify it.

    Parameters
    ----------
    nights : list of NightSamples
    model_dir : path, optional
        Default :func:`default_model_dir`.

    Returns
    -------
    dict
        Parameter (``"floor_area"``, ``"c_f"``, ``"u_walls"`` with the default ranges) →
        :class:`ClassResult`.

    Raises
    ------
    InputError
        No nights, or no usable trained models (telling the user to run ``impctl train``).
    """
    return classify_with(nights, *load_classifiers(model_dir))


def load_classifiers(model_dir: str | Path | None = None) -> tuple[dict, dict]:
    """What :func:`classify_with` takes — (models, metadata) — for ``impctl fit`` and every
    fleet worker alike: the compact forests (:mod:`.compact`) when they hold every model with
    its ranges, else the pickled ones (:func:`load_models`), set to predict in this thread.

    Raises
    ------
    InputError
        As :func:`load_models`.
    """
    directory = Path(model_dir) if model_dir is not None else default_model_dir()
    meta = _metadata(directory)
    names = list(meta.get("parameters", {}))
    compact = load_compact(directory, names) if meta.get("compact") and names else None
    if compact is not None and all(
            [list(r) for r in compact[n].ranges] == meta["parameters"][n].get("ranges")
            for n in names):   # no scikit-learn, no unpickling: ~1.4 s less per impctl fit
        return compact, meta
    models, meta = load_models(directory)
    for model in models.values():
        # One campaign row walks the trees in milliseconds: a joblib pool (n_jobs=-1 from
        # training) costs more than it saves, and inside a daemonic Dask worker joblib cannot
        # start one — scikit-learn then warned on every prediction of every fleet batch.
        forest = getattr(model, "forest_", None)
        if forest is not None:
            forest.set_params(n_jobs=1)
    return models, meta


def classify_with(nights: list[NightSamples], models: dict, meta: dict
                  ) -> dict[str, ClassResult]:
    """:func:`classify_nights` with models already loaded by :func:`load_classifiers` (a
    fleet worker loads them once)."""
    if not nights:
        raise InputError("no nights to classify")
    off = off_protocol(nights, meta)
    if off:
        nights = [n for n in nights if n.night_id not in off]
        if not nights:
            raise InputError("no night ran at a setpoint the classifiers were trained on ("
                             + _protocol_text(meta) + "): " + "; ".join(off.values()))
    lag = float(meta.get("emission_lag_h", 1.0))
    row = campaign_features([night_features(n, lag) for n in nights])
    x = pd.DataFrame([row], columns=list(CAMPAIGN_FEATURE_NAMES))
    out = {}
    for name, model in models.items():
        proba = model.predict_proba(x)[0]
        probabilities = {str(c): float(p) for c, p in zip(model.classes_, proba, strict=True)}
        common = {"parameter": name, "probabilities": probabilities,
                  "calibrated": bool(getattr(model, "calibrated_", False)),
                  "nights_left_out": tuple(off.values())}
        if not getattr(model, "determined_", True):
            # no class: the whole prior range, its classes weighted by their frequencies
            hull = (float(model.ranges[0][0]), float(model.ranges[-1][1]))
            out[name] = ClassResult(label=range_label(*hull), range=hull, probability=1.0,
                                    search_range=hull, determined=False, **common)
            continue
        best = int(np.argmax(proba))
        out[name] = ClassResult(
            label=str(model.classes_[best]),
            range=tuple(float(v) for v in model.ranges[best]),  # type: ignore[arg-type]
            probability=float(proba[best]),
            search_range=credible_hull(model.ranges, proba),
            **common,
        )
    return out


def credible_hull(ranges, proba, level: float = SEARCH_LEVEL) -> tuple[float, float]:
    """(low, high) hull of the most probable ``ranges`` whose probabilities ``proba`` add up
    to ``level`` (ties and the last class needed included); contiguous ranges, so the hull
    also holds any less probable class between two chosen ones."""
    p = np.asarray(proba, float)
    order = np.argsort(-p, kind="stable")
    need = int(np.searchsorted(np.cumsum(p[order]), level * p.sum() - 1e-12)) + 1
    last = p[order[min(need, len(order)) - 1]]
    chosen = np.flatnonzero(p >= last)   # a class as probable as the last one needed goes too
    return (float(min(ranges[i][0] for i in chosen)), float(max(ranges[i][1] for i in chosen)))


#: Two setpoints closer than this are the same night plan [K] (setpoints are written in 0.1 K).
_SETPOINT_TOL_K = 0.05


def off_protocol(nights: list[NightSamples], meta: dict) -> dict[str, str]:
    """Nights that ran at a setpoint the classifiers' population never ran: night id → why.

    The forests learnt what a night at 21 °C (constrained) or 22/23/24 °C (normal) looks like
    (``models.json`` → ``dataset.imp``); the same house at another setpoint gives other
    features, and a class read from them would be a number nobody can stand behind. Nights
    without a known setpoint, and models that record no protocol, are kept as they are.
    """
    imp = (meta.get("dataset") or {}).get("imp") or {}
    normal = [float(s) for s in imp.get("setpoints_c") or []]
    cons = imp.get("constrained_setpoint_c")
    cons = normal if cons is None else [float(cons)]   # None: the population cycled them
    allowed = {"normal": (normal, _SETPOINT_TOL_K),
               "constrained": (cons, _SETPOINT_TOL_K + float(imp.get("constrained_jitter_k", 0)))}
    out = {}
    for n in nights:
        ok, tol = allowed.get(n.kind, ([], 0.0))
        sp = float(n.setpoint_c)
        if not ok or not np.isfinite(sp) or any(abs(sp - s) < tol for s in ok):
            continue
        out[n.night_id] = f"{n.night_id} ({n.kind} at {sp:g} °C)"
    return out


def _protocol_text(meta: dict) -> str:
    imp = (meta.get("dataset") or {}).get("imp") or {}
    normal = "/".join(f"{float(s):g}" for s in imp.get("setpoints_c") or [])
    cons = imp.get("constrained_setpoint_c")
    return (f"constrained nights at {float(cons):g} °C, " if cons is not None else "") + \
        f"normal nights at {normal} °C"
