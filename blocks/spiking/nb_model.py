"""Naive Bayes models over spike features of time windows: fitting, the file format, and scoring.

Two likelihoods, one per feature kind (:mod:`flowtact.blocks.spiking.window_features`):
``counts`` → multinomial (spike counts per unit and sub-bin; additive smoothing ``alpha``) and
``latency`` → Gaussian (first-spike latency per unit, as a fraction of the window; variances
smoothed by ``var_smoothing`` × the largest feature variance). The formulas are scikit-learn's
``MultinomialNB`` and ``GaussianNB`` (with ``fit_prior=True``), which the tests use as the oracle;
scores are log-domain throughout, the posterior a log-sum-exp normalisation.

File format (``.npz``, no pickled objects): the arrays ``class_log_prior`` (C,), then
``feature_log_prob`` (C, F) for a multinomial model or ``theta`` and ``var`` (C, F) for a
Gaussian one, and ``meta``: a JSON text holding the format version, the likelihood and feature
kind, the classes, ``n_units``, ``n_bins``, the provenance (how it was trained) and a SHA-256 of
the arrays, which :func:`load_model` checks, so a damaged or hand-edited file is refused.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from flowtact.errors import FlowtactError

__all__ = [
    "FORMAT",
    "ModelError",
    "NaiveBayesModel",
    "fit_gaussian",
    "fit_multinomial",
    "load_model",
    "log_posterior",
    "save_model",
]

#: Format tag written in every model file's meta (bumped when the layout changes).
FORMAT = "flowtact-naive-bayes/1"
FeatureKind = Literal["counts", "latency"]
_ARRAYS = {
    "multinomial": ("class_log_prior", "feature_log_prob"),
    "gaussian": ("class_log_prior", "theta", "var"),
}


class ModelError(FlowtactError, ValueError):
    """A naive Bayes model file that cannot be used: unreadable, damaged, or not what was expected."""


@dataclass(frozen=True)
class NaiveBayesModel:
    """A fitted naive Bayes classifier over window features (arrays as described in the module doc)."""

    features: FeatureKind
    classes: tuple[str, ...]
    n_units: int
    n_bins: int
    arrays: Mapping[str, np.ndarray]
    provenance: Mapping[str, Any] = field(default_factory=dict)

    @property
    def likelihood(self) -> str:
        """``multinomial`` for counts, ``gaussian`` for latencies."""
        return "multinomial" if self.features == "counts" else "gaussian"

    @property
    def n_features(self) -> int:
        """Features per window: n_bins · n_units counts, or n_units latencies."""
        return self.n_units * (self.n_bins if self.features == "counts" else 1)

    def joint_log_likelihood(self, x: np.ndarray) -> np.ndarray:
        """log p(class) + log p(x | class) for feature rows ``x`` (n, F) → (n, C)."""
        x = np.asarray(x, np.float64).reshape(-1, self.n_features)
        a = self.arrays
        if self.features == "counts":
            return x @ a["feature_log_prob"].T + a["class_log_prior"]
        var, theta = a["var"], a["theta"]
        norm = -0.5 * np.sum(np.log(2.0 * np.pi * var), axis=1)
        sq = ((x[:, None, :] - theta[None, :, :]) ** 2 / var[None, :, :]).sum(axis=2)
        return a["class_log_prior"] + norm - 0.5 * sq

    def unit_marginal(self) -> NaiveBayesModel:
        """The same counts model over per-unit counts summed across sub-bins (exact marginal of a
        multinomial): what a partial window, whose sub-bins are not known yet, is scored with."""
        if self.features != "counts":
            raise ModelError("only a counts (multinomial) model has a per-unit marginal")
        flp = self.arrays["feature_log_prob"].reshape(len(self.classes), self.n_bins, self.n_units)
        marg = np.logaddexp.reduce(flp, axis=1)
        arrays = {"class_log_prior": self.arrays["class_log_prior"], "feature_log_prob": marg}
        return NaiveBayesModel("counts", self.classes, self.n_units, 1, arrays, self.provenance)


def log_posterior(model: NaiveBayesModel, x: np.ndarray) -> np.ndarray:
    """log p(class | x) for feature rows ``x`` (n, F) → (n, C), normalised by log-sum-exp."""
    jll = model.joint_log_likelihood(x)
    top = jll.max(axis=1, keepdims=True)
    return jll - (top + np.log(np.exp(jll - top).sum(axis=1, keepdims=True)))


def _class_index(y: Sequence[str], classes: Sequence[str]) -> np.ndarray:
    pos = {c: i for i, c in enumerate(classes)}
    missing = sorted(set(y) - set(pos))
    if missing:
        raise ModelError(f"labels {missing} are not among the classes {list(classes)}")
    return np.array([pos[c] for c in y], dtype=np.int64)


def _prior(idx: np.ndarray, n_classes: int) -> np.ndarray:
    counts = np.bincount(idx, minlength=n_classes).astype(np.float64)
    if (counts == 0).any():
        raise ModelError("every class needs at least one training window (some have none)")
    return np.log(counts) - np.log(counts.sum())


def fit_multinomial(
    x: np.ndarray, y: Sequence[str], classes: Sequence[str], *, n_units: int, n_bins: int, alpha: float = 1.0
) -> NaiveBayesModel:
    """Fit a multinomial naive Bayes on count rows ``x`` (n, n_bins·n_units), as MultinomialNB."""
    if alpha <= 0:
        raise ModelError(f"alpha must be > 0; got {alpha}")
    x = np.asarray(x, np.float64)
    idx = _class_index(y, classes)
    fc = np.zeros((len(classes), x.shape[1]))
    np.add.at(fc, idx, x)
    fc += alpha
    flp = np.log(fc) - np.log(fc.sum(axis=1, keepdims=True))
    arrays = {"class_log_prior": _prior(idx, len(classes)), "feature_log_prob": flp}
    return NaiveBayesModel("counts", tuple(classes), n_units, n_bins, arrays)


def fit_gaussian(
    x: np.ndarray, y: Sequence[str], classes: Sequence[str], *, n_units: int, var_smoothing: float = 1e-9
) -> NaiveBayesModel:
    """Fit a Gaussian naive Bayes on latency rows ``x`` (n, n_units), as GaussianNB."""
    x = np.asarray(x, np.float64)
    idx = _class_index(y, classes)
    prior = _prior(idx, len(classes))
    eps = var_smoothing * float(np.var(x, axis=0).max())
    theta = np.stack([x[idx == c].mean(axis=0) for c in range(len(classes))])
    var = np.stack([x[idx == c].var(axis=0) for c in range(len(classes))]) + eps
    if not (var > 0).all():
        raise ModelError(
            "a latency feature has zero variance everywhere; set var_smoothing > 0 on varied data"
        )
    arrays = {"class_log_prior": prior, "theta": theta, "var": var}
    return NaiveBayesModel("latency", tuple(classes), n_units, 1, arrays)


def _digest(arrays: Mapping[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k], np.float64)
        h.update(k.encode() + str(a.shape).encode() + a.tobytes())
    return h.hexdigest()


def save_model(path: str | Path, model: NaiveBayesModel, provenance: Mapping[str, Any] | None = None) -> Path:
    """Write ``model`` (with ``provenance``, JSON-able) to ``path`` (.npz); returns the path."""
    path = Path(path)
    arrays = {k: np.asarray(model.arrays[k], np.float64) for k in _ARRAYS[model.likelihood]}
    meta = {
        "format": FORMAT,
        "likelihood": model.likelihood,
        "features": model.features,
        "classes": list(model.classes),
        "n_units": int(model.n_units),
        "n_bins": int(model.n_bins),
        "provenance": dict(provenance if provenance is not None else model.provenance),
        "sha256": _digest(arrays),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        np.savez(f, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)
    return path


def load_model(path: str | Path) -> NaiveBayesModel:
    """Read and check a model file; raise :class:`ModelError` saying what is wrong with it."""
    path = Path(path)
    try:
        with path.open("rb") as f, np.load(f, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            stored = {k: np.array(z[k], np.float64) for k in z.files if k != "meta"}
    except FileNotFoundError:
        raise ModelError(f"{path}: no such model file") from None
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError) as e:
        raise ModelError(f"{path}: not a readable naive Bayes model file ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ModelError(
            f"{path}: format {meta.get('format') if isinstance(meta, dict) else '?'!r}, expected {FORMAT!r}"
        )
    return _checked(path, meta, stored)


def _checked(path: Path, meta: dict[str, Any], stored: dict[str, np.ndarray]) -> NaiveBayesModel:
    likelihood, features = meta.get("likelihood"), meta.get("features")
    if (likelihood, features) not in {("multinomial", "counts"), ("gaussian", "latency")}:
        raise ModelError(f"{path}: unknown likelihood/features {likelihood!r}/{features!r}")
    names = _ARRAYS[likelihood]
    if set(stored) != set(names):
        raise ModelError(f"{path}: arrays {sorted(stored)}, expected {sorted(names)}")
    if _digest(stored) != meta.get("sha256"):
        raise ModelError(f"{path}: checksum mismatch: the model arrays were changed or damaged")
    classes = tuple(str(c) for c in meta.get("classes", ()))
    n_units, n_bins = int(meta.get("n_units", 0)), int(meta.get("n_bins", 0))
    model = NaiveBayesModel(features, classes, n_units, n_bins, stored, meta.get("provenance", {}))
    want = {"class_log_prior": (len(classes),)} | {k: (len(classes), model.n_features) for k in names[1:]}
    for k, shape in want.items():
        if stored[k].shape != shape:
            raise ModelError(f"{path}: array {k} has shape {stored[k].shape}, expected {shape}")
    if not classes or n_units < 1 or n_bins < 1 or len(set(classes)) != len(classes):
        raise ModelError(f"{path}: needs distinct classes, n_units >= 1 and n_bins >= 1")
    bad = [k for k, a in stored.items() if not np.isfinite(a).all()]
    if bad or (likelihood == "gaussian" and not (stored["var"] > 0).all()):
        raise ModelError(f"{path}: non-finite or non-positive values in {bad or ['var']}")
    return model
