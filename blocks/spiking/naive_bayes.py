"""``naive_bayes``: decode a population's spikes window by window with a naive Bayes model from a file."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

import flowtact.api as ft
from flowtact.blocks.spiking.nb_model import (
    NOT_CLASSIFIED,
    ModelError,
    NaiveBayesModel,
    decide,
    load_model,
    log_posterior,
    tempered_log_posterior,
)
from flowtact.blocks.spiking.window_features import window_features

__all__ = ["EXAMPLE_MODEL", "NaiveBayes", "NaiveBayesConfig", "example_model_path"]

#: The small model the block's example runs on (fit by ``tests/blocks/spiking/test_naive_bayes.py``).
EXAMPLE_MODEL = "naive_bayes_example.npz"


def example_model_path() -> Path:
    """Path of the example model shipped in the package (``flowtact/blocks/spiking/models/``)."""
    return Path(str(resources.files("flowtact.blocks.spiking").joinpath("models", EXAMPLE_MODEL)))


@dataclass(frozen=True)
class NaiveBayesConfig(ft.Config):
    """Parameters of :class:`NaiveBayes`."""

    model: str = ft.param(
        doc="model file (.npz) written by a trainer, e.g. flowtact train-braille", path=True
    )
    gap: tuple[str, ...] = ft.param(
        ("gap",),
        doc="window categories that are not windows (between characters); ignored without categories",
    )
    threshold: float = ft.param(
        0.0,
        doc="reject option: a window whose largest posterior probability is below this is decided "
        "'not classified' (index n_classes); 0 never abstains",
        ge=0,
        le=1,
    )
    window_labels: bool = ft.param(
        True,
        doc="the window values name what is read (a categorical stream, or class indices), so the "
        "summary scores the decisions; false for windows that only delimit (braille_cell_windows)",
    )


class NaiveBayes(ft.Block):
    """Naive Bayes decoding of spike windows: a posterior over the classes and a decision per window.

    Config
    ------
    ``model`` (the file; its features, classes, units and sub-bins come from it), ``gap``, the
    reject ``threshold`` and ``window_labels``.

    Notes
    -----
    Features (:mod:`~flowtact.blocks.spiking.window_features`): spike counts per unit in
    ``n_bins`` time-normalised sub-bins (multinomial likelihood) or first-spike latencies per unit
    as a fraction of the window (Gaussian); the model file (:mod:`~flowtact.blocks.spiking.nb_model`)
    says which. Scores are log-domain and normalised by log-sum-exp: an empty window gives the
    prior, never NaN. A window's result waits until the spike watermark passes its end, so the
    output is the same whatever the chunking. A window still open at end of stream is dropped
    (``unfinished_windows``). Window values that are no category index count as gaps.
    With ``threshold`` > 0 the decoder may abstain (:func:`~flowtact.blocks.spiking.nb_model.decide`):
    a window whose largest posterior probability is below it is decided ``not classified``, a
    category of its own after the classes (``not_classified``).

    Example
    -------
    >>> from flowtact.blocks.spiking.naive_bayes import NaiveBayes
    >>> from flowtact.testing import run_block_example
    >>> out = run_block_example(NaiveBayes)
    >>> out["decision"].data.tolist()  # the example's windows are classes 0, 1, 2, 0, 2
    [0, 1, 2, 0, 2]
    """

    config_cls = NaiveBayesConfig
    inputs = {
        "spikes": ft.Port(
            dtype="int64",
            shape=(),
            events=True,
            doc=(
                "the population's spikes (e.g. nlif.spikes), watermarked (Chunk.end); n_units must be the"
                " model's"
            ),
        ),
        "window": ft.Port(
            dtype=None,
            shape=(),
            require_rate=True,
            doc=(
                "what is under the sensor: a categorical stream (e.g. the character), int or float, with "
                "a rate; a window is a maximal run of one value that is not named in gap. Without "
                "categories, values < 0 are gaps; float values that are no whole number (NaN) are gaps "
                "too (unknown_window_values)"
            ),
        ),
    }
    outputs = {
        "posterior": ft.Port(
            dtype="float64",
            units="1",
            doc=(
                "p(class | features of the window), shape (n_classes,), one sample per finished window, "
                "stamped at its end, no rate; the channels are named after the classes"
            ),
        ),
        "decision": ft.Port(
            dtype="int64",
            shape=(),
            units="1",
            doc=(
                "the most probable class (the first of equals), categorical (the classes, then 'not "
                "classified' when threshold > 0: the largest probability was below it), one sample per"
                " finished window, stamped at its end"
            ),
        ),
        "running": ft.Port(
            dtype="float64",
            units="1",
            doc=(
                "at each window sample t (at the window stream's rate): the posterior from the spikes "
                "since the window began up to t + 1/rate, scored with the unit-marginal model (the "
                "per-unit counts over all sub-bins, since where the window ends is not known yet) with "
                "its evidence scaled by the model's running_temperature (a calibration: see nb_model); in"
                " a gap, the last window's posterior (the prior before the first). What a speed "
                "controller reads; a latency model refuses to run when this output is consumed (a latency"
                " needs the window's end)"
            ),
        ),
    }
    counter_docs = {
        "windows": "windows decoded (posterior and decision emitted): the normal work",
        "not_classified": "windows decided 'not classified' (largest posterior below threshold): the "
        "reject option at work",
        "empty_windows": "windows with no spike at all: decoded as the prior (the population was silent)",
        "unfinished_windows": "a window still open at end of stream: dropped, not decoded",
        "late_spikes": "spikes older than results already emitted, by more than float rounding "
        "(the producer broke its watermark): ignored; a fault upstream",
        "unknown_window_values": "window samples whose value is no category (or NaN): treated as gap; a fault upstream",
    }

    # -- specs -------------------------------------------------------------------------------
    def _model(self) -> NaiveBayesModel:
        try:
            return load_model(self.config.model)
        except ModelError as e:
            raise ft.SpecError(None, f"{self.node} ({self.name}): model: {e}") from None

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        m = self._model()
        s, w = inputs["spikes"], inputs["window"]
        if s.n_units != m.n_units:
            raise ft.SpecError(
                "spikes",
                f"{self.node}: the model {self.config.model} was trained on {m.n_units} units; input "
                f"'spikes' has {s.n_units}",
            )
        if np.dtype(w.dtype).kind not in "iuf":
            raise ft.SpecError(
                "window", f"{self.node}: input 'window' must be categorical numbers; got {w.dtype}"
            )
        if w.categories is not None:
            missing = [c for c in m.classes if c not in w.categories]
            if missing:
                raise ft.SpecError(
                    "window",
                    f"{self.node}: model classes {missing} are not among the window categories "
                    f"{list(w.categories)}: the model was trained on another alphabet",
                )
        c = len(m.classes)
        post = ft.StreamSpec(dtype="float64", shape=(c,), units="1", labels=m.classes)
        return {
            "posterior": post,
            "decision": ft.StreamSpec(dtype="int64", shape=(), units="1", categories=self._decisions(m)),
            "running": post.with_(rate_hz=w.rate_hz),
        }

    def _decisions(self, m: NaiveBayesModel) -> tuple[str, ...]:
        """The decision's categories: the classes, and 'not classified' when the decoder may abstain."""
        return (*m.classes, NOT_CLASSIFIED) if self.config.threshold > 0 else m.classes

    # -- state -------------------------------------------------------------------------------
    def reset(self) -> None:
        self._m = self._model()
        if self._m.features != "counts" and "running" in self.demanded:
            raise ft.SpecError(
                None,
                f"{self.node} ({self.name}): output 'running' needs a counts model; {self.config.model} "
                "has latency features",
            )
        self._marg = self._m.unit_marginal() if self._m.features == "counts" else None
        w = self.input_specs["window"]
        self._dt = 1.0 / float(w.rate_hz)  # type: ignore[arg-type]
        cats = w.categories
        self._n_values = len(cats) if cats is not None else None
        self._gaps = frozenset(i for i, c in enumerate(cats) if c in self.config.gap) if cats else frozenset()
        self._n_units = self._m.n_units
        self._spk_t = np.zeros(0)
        self._spk_i = np.zeros(0, np.int64)
        self._wm = -math.inf
        self._cur: tuple[int, float] | None = None  # (value, start) of the open window
        self._queue: deque[tuple[str, float, float, int]] = deque()  # ("win"|"run", start, need, value)
        self._labels = tuple(cats) if cats is not None else None
        self._read: list[tuple[str, bool | None]] = []  # per decoded window: (class, right or unknown)
        self._last = np.exp(self._m.arrays["class_log_prior"])
        self._keep_from = -math.inf
        self._t_last = -math.inf  # time of the last window sample
        self._decided = -math.inf  # spikes before this time were needed by results already emitted

    def _values(self, data: np.ndarray) -> np.ndarray:
        """Window values as ints; a float that is no whole number (NaN, 2.5) becomes ``_BAD``."""
        d = np.asarray(data)
        if d.dtype.kind != "f":
            return d.astype(np.int64)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(d) & (d == np.round(d)) & (np.abs(d) < 2**53)
        return np.where(ok, np.where(ok, d, 0).astype(np.int64), _BAD)

    def _is_gap(self, v: int) -> bool:
        if v == _BAD:
            self.count("unknown_window_values")
            return True
        if self._n_values is None:
            return v < 0
        if not 0 <= v < self._n_values:
            self.count("unknown_window_values")
            return True
        return v in self._gaps

    # -- step --------------------------------------------------------------------------------
    def step(self, spikes: ft.Chunk, window: ft.Chunk) -> dict[str, ft.Chunk]:
        self._take_spikes(spikes)
        for t, v in zip(window.t.tolist(), self._values(window.data).tolist(), strict=True):
            self._take_window_sample(float(t), v)
        return self._drain(final=False)

    def _take_spikes(self, spikes: ft.Chunk) -> None:
        if len(spikes):
            idx = np.asarray(spikes.data, np.int64)
            if idx.min() < 0 or idx.max() >= self._n_units:
                raise ValueError(
                    f"{self.node} ({self.name}): unit index out of range 0..{self._n_units - 1} "
                    f"(got {idx.min()}..{idx.max()})"
                )
            t = np.asarray(spikes.t, np.float64)
            # before a result already emitted, beyond rounding: the producer broke its watermark
            late = t < self._decided - SAME_INSTANT_S
            if late.any():
                self.count("late_spikes", int(late.sum()))
                t, idx = t[~late], idx[~late]
            self._spk_t = np.concatenate([self._spk_t, t])
            self._spk_i = np.concatenate([self._spk_i, idx])
            if len(t) and (np.diff(self._spk_t) < 0).any():  # searchsorted needs time order
                order = np.argsort(self._spk_t, kind="stable")
                self._spk_t, self._spk_i = self._spk_t[order], self._spk_i[order]
            if len(t):
                self._wm = max(self._wm, float(t.max()))
        if spikes.end is not None:
            self._wm = max(self._wm, float(spikes.end))

    def _take_window_sample(self, t: float, v: int) -> None:
        gap = self._is_gap(v)
        self._t_last = t
        if self._cur is not None and (gap or v != self._cur[0]):
            self._queue.append(("win", self._cur[1], t, self._cur[0]))  # the window [start, t) is finished
            self._cur = None
        if not gap and self._cur is None:
            self._cur = (v, t)
        start = self._cur[1] if self._cur is not None else math.nan
        self._queue.append(("run", start, t + self._dt, v))

    def _drain(self, final: bool) -> dict[str, ft.Chunk]:
        c = len(self._m.classes)
        post_t, post, dec, run_t, run = [], [], [], [], []
        while self._queue and (final or self._queue[0][2] <= self._wm):
            kind, start, need, value = self._queue.popleft()
            self._decided = max(self._decided, need)
            if kind == "win":
                p = self._decode(start, need)
                self._last = p
                post_t.append(need)
                post.append(p)
                dec.append(int(decide(p[None, :], self.config.threshold)[0]))
                if dec[-1] == c:
                    self.count("not_classified")
                self._tell(dec[-1], value)
            else:
                run_t.append(need - self._dt)
                run.append(self._running(start, need))
        self._prune()
        end = self._wm if math.isfinite(self._wm) else None
        return {
            "posterior": ft.Chunk(np.array(post_t), np.array(post).reshape(-1, c), end),
            "decision": ft.Chunk(np.array(post_t), np.array(dec, np.int64), end),
            "running": ft.Chunk(np.array(run_t), np.array(run).reshape(-1, c), end),
        }

    def _tell(self, decided: int, value: int) -> None:
        """Keep what a window was read as, and whether that is its label (the window stream's own
        category name, or its value where the stream has no categories; unknown without
        ``window_labels``), for :meth:`summary`."""
        name = self._decisions(self._m)[decided]
        right: bool | None
        if not self.config.window_labels:
            right = None
        elif decided == len(self._m.classes):
            right = False
        elif self._labels is not None:
            right = 0 <= value < len(self._labels) and self._labels[value] == name
        else:
            right = value == decided
        self._read.append((name, right))

    def summary(self) -> str | None:
        """``read 26 windows, 26 right (against the window labels): "qwerty…"`` (``, 2 not
        classified`` with a threshold; no score without ``window_labels``, where an abstention is
        shown as ``?``); None if none was read."""
        if not self._read:
            return None
        names = ["?" if n == NOT_CLASSIFIED else n for n, _ in self._read]
        right = sum(1 for _, r in self._read if r)
        text = "".join(names) if all(len(n) == 1 for n in names) else " ".join(names)
        if len(text) > SUMMARY_TEXT_CHARS:
            text = text[: SUMMARY_TEXT_CHARS - 1] + "…"
        abstained = sum(1 for n, _ in self._read if n == NOT_CLASSIFIED)
        rejects = f", {abstained} not classified" if self.config.threshold > 0 else ""
        if not self.config.window_labels:
            return f'read {len(names)} windows{rejects}: "{text}"'
        return f'read {len(names)} windows, {right} right{rejects} (against the window labels): "{text}"'

    def _decode(self, t0: float, t1: float) -> np.ndarray:
        m = self._m
        x = window_features(
            self._spk_t,
            self._spk_i,
            np.array([[t0, t1 - SAME_INSTANT_S]]),
            n_units=m.n_units,
            n_bins=m.n_bins,
            kind=m.features,
        )
        self.count("windows")
        silent = (x == 0.0) if m.features == "counts" else (x == 1.0)
        if silent.all():
            self.count("empty_windows")
        return np.exp(log_posterior(m, x)[0])

    def _running(self, start: float, need: float) -> np.ndarray:
        if math.isnan(start) or self._marg is None:
            return self._last.copy()
        x = window_features(
            self._spk_t, self._spk_i, np.array([[start, need - SAME_INSTANT_S]]), n_units=self._n_units
        )
        return np.exp(tempered_log_posterior(self._marg, x, self._m.running_temperature)[0])

    def _prune(self) -> None:
        """Forget spikes no open or queued window can need."""
        starts = [s for _k, s, _n, _v in self._queue if not math.isnan(s)]
        if self._cur is not None:
            starts.append(self._cur[1])
        keep = min(starts) if starts else self._t_last  # the next window starts after the last sample
        if keep > self._keep_from:
            self._keep_from = keep
            cut = int(np.searchsorted(self._spk_t, keep, side="left"))
            if cut:
                self._spk_t, self._spk_i = self._spk_t[cut:], self._spk_i[cut:]

    def flush(self) -> dict[str, ft.Chunk]:
        if self._cur is not None:
            self.count("unfinished_windows")
            self._cur = None
        return self._drain(final=True)

    @classmethod
    def example(cls) -> ft.Example:
        spikes, window = example_data()
        return ft.Example(
            params={"model": str(example_model_path())},
            inputs={"spikes": spikes, "window": window},
            rate_hz=EXAMPLE_RATE_HZ,
        )


#: Times closer than this are one instant (s). A window ends at ``t + 1/rate`` and a producer's
#: watermark is its last sample's ``t + dt``, sums that float rounding can put an ulp past the next
#: sample's own time ``(i + 1) / rate`` (0.068 + 0.004 = 0.07200000000000001 > 0.072): a spike at
#: that next sample is neither late nor inside the window that ends there. 1 ns is far below any
#: sample period and far above the rounding of times up to days.
SAME_INSTANT_S = 1e-9

#: At most this many characters of the decoded text in :meth:`NaiveBayes.summary`.
SUMMARY_TEXT_CHARS = 60

#: Stand-in for a window value that is no whole number (NaN, inf, 2.5): counted, treated as gap.
_BAD = np.iinfo(np.int64).min

#: Sample rate of the example's window stream (the Braille loop's 4 ms tick).
EXAMPLE_RATE_HZ = 250.0


def example_data(
    labels: tuple[int, ...] = (0, 1, 2, 0, 2), seed: int = 3
) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Synthetic spikes of 4 units over windows of 3 classes (each class drives its own units,
    Poisson), 0.2 s windows separated by 0.08 s gaps (-1), at :data:`EXAMPLE_RATE_HZ`."""
    rng = np.random.default_rng(seed)
    rates = np.array([[60.0, 40.0, 5.0, 5.0], [5.0, 50.0, 50.0, 5.0], [5.0, 5.0, 40.0, 70.0]])
    win, gap = 50, 20
    window = np.full(gap + len(labels) * (win + gap), -1, np.int64)
    ts, us = [], []
    for k, c in enumerate(labels):
        a = gap + k * (win + gap)
        window[a : a + win] = c
        t0, t1 = a / EXAMPLE_RATE_HZ, (a + win) / EXAMPLE_RATE_HZ
        for u, r in enumerate(rates[c]):
            n = rng.poisson(r * (t1 - t0))
            ts.append(np.sort(rng.uniform(t0, t1, n)))
            us.append(np.full(n, u, np.int64))
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    return (t[order], np.concatenate(us)[order]), window
