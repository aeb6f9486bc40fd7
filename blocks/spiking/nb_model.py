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
kind, the classes, ``n_units``, ``n_bins``, ``running_temperature``, the provenance (how it was
trained) and a SHA-256 of the arrays and of those fields, which :func:`load_model` checks, so a
damaged or hand-edited file is refused.

``running_temperature`` (τ, default 1) scales the evidence of a *partial* window scored with the
unit-marginal model: ``log p(c | x) ∝ log p(c) + τ · log p(x | c)``. Counts from the first part of a
window are not distributed like a whole window's, so the plain marginal is over-confident; τ is
fitted on the training windows' prefixes (:func:`fit_temperature`, minimum log-loss), as in
temperature scaling of classifiers.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

import flowtact.api as ft
from flowtact.errors import FileRefused
from flowtact.inputs.bounded_files import read_npz_bounded
from flowtact.inputs.safe_text import shown

__all__ = [
    "FORMAT",
    "NOT_CLASSIFIED",
    "ModelError",
    "NaiveBayesModel",
    "decide",
    "fit_gaussian",
    "fit_multinomial",
    "fit_temperature",
    "load_model",
    "log_posterior",
    "save_model",
    "tempered_log_posterior",
]

#: Format tag written in every model file's meta (bumped when the layout changes).
FORMAT = "flowtact-naive-bayes/1"
FeatureKind = Literal["counts", "latency"]
MAX_MODEL_BYTES = 64 << 20
"""Most bytes of arrays a model file may hold (checked from its headers before reading; the Braille
models are a few hundred kB)."""
MAX_CLASSES = 10_000
"""Most classes a model may have."""
MAX_UNITS = 1_000_000
"""Most input units a model may expect."""
MAX_BINS = 10_000
"""Most sub-bins per window a counts model may use."""
_META_CHARS = 1 << 20
_ARRAYS = {
    "multinomial": ("class_log_prior", "feature_log_prob"),
    "gaussian": ("class_log_prior", "theta", "var"),
}


class ModelError(ft.FlowtactError, ValueError):
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
    running_temperature: float = 1.0

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

    def running_log_posterior(self, x: np.ndarray) -> np.ndarray:
        """log p(class | per-unit counts ``x`` of a partial window): the unit-marginal model with
        its evidence scaled by ``running_temperature``."""
        return tempered_log_posterior(
            self.unit_marginal(), np.asarray(x, np.float64), self.running_temperature
        )


def tempered_log_posterior(marg: NaiveBayesModel, x: np.ndarray, tau: float) -> np.ndarray:
    """log p(class | x) of a unit-marginal counts model with the evidence scaled by ``tau``."""
    prior = marg.arrays["class_log_prior"]
    jll = prior + tau * (x.reshape(-1, marg.n_units) @ marg.arrays["feature_log_prob"].T)
    top = jll.max(axis=1, keepdims=True)
    return jll - (top + np.log(np.exp(jll - top).sum(axis=1, keepdims=True)))


def fit_temperature(model: NaiveBayesModel, x: np.ndarray, y: Sequence[str]) -> float:
    """τ in [1e-3, 1] minimising the log-loss of the tempered unit-marginal posterior on per-unit
    prefix counts ``x`` (n, n_units) of windows of classes ``y`` (a grid in log τ, then refined)."""
    marg = model.unit_marginal()
    idx = _class_index(y, model.classes)
    x = np.asarray(x, np.float64)

    def loss(log_tau: float) -> float:
        return float(
            -tempered_log_posterior(marg, x, float(np.exp(log_tau)))[np.arange(len(idx)), idx].mean()
        )

    grid = np.linspace(np.log(1e-3), 0.0, 40)
    best = grid[int(np.argmin([loss(g) for g in grid]))]
    fine = np.linspace(best - 0.2, min(best + 0.2, 0.0), 21)
    return float(np.exp(fine[int(np.argmin([loss(g) for g in fine]))]))


#: The decision of a window whose largest posterior probability is below the threshold: its own
#: category, after the classes (index ``n_classes``).
NOT_CLASSIFIED = "not classified"


def decide(posterior: np.ndarray, threshold: float = 0.0) -> np.ndarray:
    """The decision rule with a reject option (Chow 1970), shared by ``naive_bayes`` and the bench:
    for posterior rows ``(n, C)``, the most probable class (the first of equals), or ``C`` (
    :data:`NOT_CLASSIFIED`) where the largest probability is below ``threshold`` (0: never)."""
    p = np.asarray(posterior, np.float64).reshape(len(posterior), -1)
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"threshold must be in [0, 1]; got {threshold}")
    best = np.argmax(p, axis=1).astype(np.int64)
    return np.where(p.max(axis=1, initial=-np.inf) < threshold, p.shape[1], best)


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


def _digest(arrays: Mapping[str, np.ndarray], fields: Mapping[str, Any]) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k], np.float64)
        h.update(k.encode() + str(a.shape).encode() + a.tobytes())
    h.update(json.dumps(dict(fields), sort_keys=True).encode())
    return h.hexdigest()


def _fields(meta: Mapping[str, Any]) -> dict[str, Any]:
    """The meta fields the checksum covers (what scoring depends on)."""
    keys = ("likelihood", "features", "classes", "n_units", "n_bins", "running_temperature")
    return {k: meta.get(k) for k in keys}


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
        "running_temperature": float(model.running_temperature),
        "provenance": dict(provenance if provenance is not None else model.provenance),
    }
    meta["sha256"] = _digest(arrays, _fields(meta))
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        np.savez(f, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)
    return path


def load_model(path: str | Path) -> NaiveBayesModel:
    """Read and check a model file; raise :class:`ModelError` saying what is wrong with it.

    The file is read within bounds (:func:`flowtact.inputs.bounded_files.read_npz_bounded`: a regular
    file, members checked against :data:`MAX_MODEL_BYTES` from their headers, no pickles), then
    every field is range-checked (classes, units, bins, finite probabilities) before use.
    """
    path = Path(path)
    try:
        z = read_npz_bounded(path, MAX_MODEL_BYTES)
    except FileNotFoundError:
        raise ModelError(f"{shown(path)}: no such model file") from None
    except FileRefused as e:
        raise ModelError(f"{shown(path)}: not a readable naive Bayes model file ({e.reason})") from None
    except OSError as e:
        raise ModelError(f"{shown(path)}: cannot be read ({shown(e.strerror or e, limit=200)})") from None
    meta = _meta(path, z.pop("meta", None))
    if meta.get("format") != FORMAT:
        raise ModelError(
            f"{shown(path)}: format {shown(repr(meta.get('format')), limit=80)}, expected {FORMAT!r}"
        )
    stored = {}
    for k, a in z.items():
        if a.dtype.kind not in "fiu":
            raise ModelError(f"{shown(path)}: array {shown(k, limit=80)} holds {a.dtype}, not numbers")
        stored[k] = np.asarray(a, np.float64)
    return _checked(path, meta, stored)


def _meta(path: Path, value: np.ndarray | None) -> dict[str, Any]:
    """The model's meta (a JSON object in a text array), or :class:`ModelError`."""
    if value is None or value.dtype.kind != "U" or value.size != 1:
        raise ModelError(f"{shown(path)}: not a naive Bayes model file (no 'meta' text)")
    text = str(value.reshape(-1)[0])
    if len(text) > _META_CHARS:
        raise ModelError(f"{shown(path)}: meta text of {len(text):,} characters (at most {_META_CHARS:,})")
    try:
        meta = json.loads(text)
    except (ValueError, RecursionError) as e:
        raise ModelError(f"{shown(path)}: meta is not JSON ({shown(e, limit=200)})") from None
    if not isinstance(meta, dict):
        raise ModelError(f"{shown(path)}: meta is not a JSON object")
    return meta


def _count(path: Path, meta: Mapping[str, Any], key: str, most: int) -> int:
    """An integer field of the meta in ``1..most``, or :class:`ModelError`."""
    value = meta.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= most:
        raise ModelError(
            f"{shown(path)}: {key} must be an integer in 1..{most:,}; got {shown(repr(value), limit=80)}"
        )
    return value


def _checked(path: Path, meta: dict[str, Any], stored: dict[str, np.ndarray]) -> NaiveBayesModel:
    likelihood, features = meta.get("likelihood"), meta.get("features")
    if (likelihood, features) not in {("multinomial", "counts"), ("gaussian", "latency")}:
        raise ModelError(
            f"{shown(path)}: unknown likelihood/features {shown(repr(likelihood), limit=80)}/"
            f"{shown(repr(features), limit=80)}"
        )
    names = _ARRAYS[likelihood]
    if set(stored) != set(names):
        raise ModelError(f"{shown(path)}: arrays {sorted(stored)}, expected {sorted(names)}")
    if _digest(stored, _fields(meta)) != meta.get("sha256"):
        raise ModelError(f"{shown(path)}: checksum mismatch: the model was changed or damaged")
    raw_classes = meta.get("classes")
    if not isinstance(raw_classes, list) or not 1 <= len(raw_classes) <= MAX_CLASSES:
        raise ModelError(f"{shown(path)}: classes must be a list of 1..{MAX_CLASSES:,} names")
    classes = tuple(str(c) for c in raw_classes)
    n_units = _count(path, meta, "n_units", MAX_UNITS)
    n_bins = _count(path, meta, "n_bins", MAX_BINS)
    tau = meta.get("running_temperature", 1.0)
    if isinstance(tau, bool) or not isinstance(tau, (int, float)) or not 0 < tau <= 1:
        raise ModelError(
            f"{shown(path)}: running_temperature must be in (0, 1]; got {shown(repr(tau), limit=80)}"
        )
    tau = float(tau)
    provenance = meta.get("provenance", {})
    model = NaiveBayesModel(features, classes, n_units, n_bins, stored, provenance, tau)
    want = {"class_log_prior": (len(classes),)} | {k: (len(classes), model.n_features) for k in names[1:]}
    for k, shape in want.items():
        if stored[k].shape != shape:
            raise ModelError(f"{shown(path)}: array {k} has shape {stored[k].shape}, expected {shape}")
    if len(set(classes)) != len(classes):
        raise ModelError(f"{shown(path)}: needs distinct classes")
    bad = [k for k, a in stored.items() if not np.isfinite(a).all()]
    if bad or (likelihood == "gaussian" and not (stored["var"] > 0).all()):
        raise ModelError(f"{shown(path)}: non-finite or non-positive values in {bad or ['var']}")
    return model
