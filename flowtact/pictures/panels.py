"""What each recorded stream is drawn as, and the drawing: one function per kind of panel.

A stream's spec decides its panels (:func:`plan_panels`): vector samples -> labelled lines per
channel in their units (a heat map beyond :data:`MAX_LINES` channels; channels whose label carries
another unit get their own panel); categorical samples -> steps named on the axis; frames -> a
thumbnail strip; spike events -> raster and firing rate; stimulation pulses (events with
``unit, amplitude, width`` columns) -> amplitude per pulse and a raster of channels. Readers come
from :mod:`flowtact.pictures.bounded_read`, so memory stays bounded.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from flowtact.pictures.bounded_read import (
    StreamSource,
    binned_event_counts,
    change_points,
    event_points,
    frames_at,
    index_range,
    sample_envelope,
)
from flowtact.pictures.units import label_unit, pretty_units

__all__ = [
    "MAX_LINES",
    "Panel",
    "binned_rates",
    "channel_names",
    "draw_frames",
    "draw_panel",
    "is_frames",
    "plan_panels",
    "rate_bin_s",
]

#: Sample streams with more channels than this are drawn as a heat map.
MAX_LINES = 12
#: Event streams with more units than this get one population-mean rate line.
MAX_RATE_LINES = 8
#: More events than this in view are drawn as binned counts rather than one tick each.
MAX_EVENT_TICKS = 100_000
#: Thumbnails in a frame strip.
THUMBNAILS = 8
#: Firing-rate bins (the paper's figures use 20 ms), widened so a plot holds at most MAX_BINS.
RATE_BIN_S = 0.02
MAX_BINS = 3000
TITLE = {"loc": "left", "fontsize": 9}


@dataclass(frozen=True)
class Panel:
    """One axes of the figure: a stream, what it is drawn as, and (for lines) which channels."""

    kind: str  # lines, heatmap, steps, raster, rate, pulses, frames
    source: StreamSource
    height: float
    channels: tuple[int, ...] = ()
    names: tuple[str, ...] = ()
    units: str = "1"
    what: str = ""


def is_frames(shape: tuple[int, ...]) -> bool:
    """Whether samples of this shape are images (the last two axes at least 8 × 8)."""
    return len(shape) >= 2 and shape[-1] >= 8 and shape[-2] >= 8


def channel_names(name: str, spec: Any) -> list[str]:
    """A name per value of a sample (C order): the spec's labels, else ``name[i]`` / ``name[i,j]``."""
    shape = tuple(spec.shape)
    size = int(np.prod(shape)) if shape else 1
    labels = list(spec.labels) if spec.labels else []
    if len(labels) == size:
        return labels
    if not shape:
        return [name]
    if len(labels) == shape[-1]:
        return [
            f"[{','.join(map(str, ix[:-1]))}] {labels[ix[-1]]}"
            for ix in itertools.product(*map(range, shape))
        ]
    return [f"{name}[{','.join(map(str, ix))}]" for ix in itertools.product(*map(range, shape))]


def _unit_groups(names: list[str], units: str) -> list[tuple[str, list[int], list[str]]]:
    """Channels grouped by unit (a label's unit suffix overrides the stream's): (unit, indices, names)."""
    groups: dict[str, tuple[list[int], list[str]]] = {}
    for i, label in enumerate(names):
        bare, unit = label_unit(label)
        idx, shown = groups.setdefault(unit or units, ([], []))
        idx.append(i)
        shown.append(bare)
    return [(u, idx, shown) for u, (idx, shown) in groups.items()]


def _event_columns(spec: Any) -> dict[str, int]:
    """Columns of multi-column events by role (``unit``, ``amplitude``, ``width``) from their labels."""
    out = {}
    for i, label in enumerate(spec.labels or ()):
        for role in ("unit", "amplitude", "width"):
            if label.lower().startswith(role):
                out.setdefault(role, i)
    return out


def n_event_units(spec: Any) -> int:
    """Rows of an event stream's raster: its ``n_units``, else one per label, else one."""
    return max(spec.n_units or (len(spec.labels) if spec.labels and not spec.shape else 1), 1)


def event_word(name: str) -> str:
    """What an event stream's events are called in its panels: ``spikes`` for a port named for
    them, else ``events`` (a block's own stream, ``env.crossings``, is not called spikes)."""
    return "spikes" if "spike" in name.rpartition(".")[2].lower() else "events"


def plan_panels(sources: dict[str, StreamSource]) -> list[Panel]:
    """The panels of every stream, in recorded order, frame strips last."""
    out: list[Panel] = []
    frames: list[Panel] = []
    for name, s in sources.items():
        spec = s.spec
        if spec.events:
            n = n_event_units(spec)
            raster_h = float(np.clip(0.8 + 0.04 * n, 1.1, 3.0))
            if s.data.ndim > 1 and "amplitude" in _event_columns(spec):
                out.append(Panel("pulses", s, 1.6))
                out.append(Panel("raster", s, raster_h, what="pulses"))
            else:
                out.append(Panel("raster", s, raster_h, what=event_word(name)))
                out.append(Panel("rate", s, 1.4))
        elif is_frames(tuple(spec.shape)):
            frames.append(Panel("frames", s, 0.0, units=spec.units))
        elif spec.categories and not spec.shape:
            out.append(Panel("steps", s, float(np.clip(0.5 + 0.25 * len(spec.categories), 1.1, 3.0))))
        else:
            names = channel_names(name, spec)
            for unit, idx, shown in _unit_groups(names, spec.units):
                kind = "lines" if len(idx) <= MAX_LINES else "heatmap"
                out.append(
                    Panel(kind, s, _height(kind, len(idx), bool(spec.labels)), tuple(idx), tuple(shown), unit)
                )
    return out + frames


def rate_bin_s(t0: float, t1: float) -> float:
    """Rate bin width: 20 ms, or wider so that ``[t0, t1]`` holds at most :data:`MAX_BINS` bins."""
    return max(RATE_BIN_S, (t1 - t0) / MAX_BINS)


def binned_rates(
    t: np.ndarray, unit: np.ndarray, n_units: int, t0: float, t1: float, bin_s: float = RATE_BIN_S
) -> tuple[np.ndarray, np.ndarray]:
    """Firing rate of each unit (spikes/s) in bins of ``bin_s`` from ``t0``: (bin starts, (bins, units))."""
    n_bins = max(int(np.ceil((t1 - t0) / bin_s - 1e-9)), 1)
    edges = t0 + bin_s * np.arange(n_bins + 1)
    keep = (t >= t0) & (t < edges[-1]) & (unit >= 0) & (unit < n_units)
    b = np.clip(np.searchsorted(edges, t[keep], side="right") - 1, 0, n_bins - 1)
    counts = np.zeros((n_bins, n_units))
    np.add.at(counts, (b, unit[keep].astype(np.int64)), 1.0)
    return edges[:-1], counts / bin_s


def _rate_edges(t0: float, t1: float) -> tuple[np.ndarray, float]:
    bin_s = rate_bin_s(t0, t1)
    n_bins = max(int(np.ceil((t1 - t0) / bin_s - 1e-9)), 1)
    return t0 + bin_s * np.arange(n_bins + 1), bin_s


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:.3g} ms" if seconds < 1 else f"{seconds:.3g} s"


def _rate_text(s: StreamSource) -> str:
    return f", {s.spec.rate_hz:g} Hz" if s.spec.rate_hz else ""


def _legend(ax: Any, n: int) -> None:
    if n > 1:
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7, frameon=False, borderaxespad=0)


def _styles(shape: tuple[int, ...], count: int) -> list[dict[str, Any]]:
    """Colour per row and line style per column for (rows, ≤ 4 columns) samples; else a colour each."""
    if len(shape) == 2 and shape[1] <= 4 and count == shape[0] * shape[1]:
        dashes = ["-", "--", ":", "-."]
        return [
            {"color": f"C{r % 10}", "linestyle": dashes[c]} for r in range(shape[0]) for c in range(shape[1])
        ]
    return [{"color": f"C{i % 10}"} for i in range(count)]


def _group_name(names: tuple[str, ...]) -> str:
    """The word every channel name of a unit group ends with (``engage``), or empty."""
    last = {n.rsplit(" ", 1)[-1] for n in names}
    return f"{last.pop()}: " if len(last) == 1 and len(names) > 1 and " " in names[0] else ""


def _draw_lines(ax: Any, p: Panel, t0: float, t1: float) -> None:
    s = p.source
    i, j = index_range(s, t0, t1)
    env = sample_envelope(s, i, j)
    total = s.spec.size
    whole = len(p.channels) == total
    styles = _styles(tuple(s.spec.shape), total) if whole else _styles((), len(p.channels))
    for k, (c, name) in enumerate(zip(p.channels, p.names, strict=True)):
        style = styles[c] if whole else styles[k]
        ax.plot(env.t, env.y[:, c], linewidth=1.0 if len(p.channels) <= 9 else 0.7, label=name, **style)
    _legend(ax, len(p.channels))
    unit = pretty_units(p.units)
    ax.set_ylabel(unit, fontsize=8)
    which = (
        _count(total, "channel") if whole else f"{_group_name(p.names)}{len(p.channels)} of {total} channels"
    )
    note = f"; min–max envelope, {env.per_point} samples per point" if env.per_point > 1 else ""
    note += _missing(ax, env, p.channels)
    ax.set_title(f"{s.name} — {which} as lines, {unit}{_rate_text(s)}{note}", **TITLE)


def _say(ax: Any, text: str) -> None:
    """Write ``text`` across an axes that has nothing to show, so an empty panel is never silent."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=9, color="0.4")


def _missing(ax: Any, env: Any, channels: tuple[int, ...]) -> str:
    """Title note (and in-axes text) for no samples or non-finite values among ``channels``."""
    if env.n == 0:
        _say(ax, "no samples in this time range")
        return "; no samples"
    bad = int(env.nonfinite[list(channels)].sum())
    if bad == env.n * len(channels):
        _say(ax, "every value is NaN or inf")
        return "; every value NaN/inf"
    return f"; {bad} NaN/inf values (gaps)" if bad else ""


def _count(n: int, word: str) -> str:
    return f"{n:,} {word}{'s' if n != 1 else ''}"


#: Most row labels a heat map writes out; beyond, every k-th (a label per row would overlap).
MAX_HEATMAP_LABELS = 40
HEATMAP_ROW_IN = 0.11
"""Height a written-out row label needs, in inches (5-point type with a little air)."""


def _height(kind: str, n: int, labelled: bool) -> float:
    """A lines panel 1.9 in; a heat map 2.4 in, taller where it writes many row labels."""
    if kind == "lines":
        return 1.9
    return max(2.4, HEATMAP_ROW_IN * min(n, MAX_HEATMAP_LABELS)) if labelled else 2.4


def _heatmap_rows(ax: Any, p: Panel, labelled: bool) -> None:
    """Name a heat map's rows: every row up to 24; a labelled stream's rows (a posterior over 26
    letters) up to :data:`MAX_HEATMAP_LABELS` in smaller type, then every k-th label; else numbers."""
    n = len(p.channels)
    if n <= 24:
        ax.set_yticks(range(n), list(p.names), fontsize=6)
    elif labelled:
        step = -(-n // MAX_HEATMAP_LABELS)
        ax.set_yticks(range(0, n, step), list(p.names)[::step], fontsize=5 if step == 1 else 6)


def _draw_heatmap(ax: Any, p: Panel, t0: float, t1: float) -> None:
    s = p.source
    i, j = index_range(s, t0, t1)
    env = sample_envelope(s, i, j, buckets=1000)
    z = env.mean[:, list(p.channels)].T
    if len(env.t_mean):
        extent = (float(env.t_mean[0]), float(env.t_mean[-1]), len(p.channels) - 0.5, -0.5)
        im = ax.imshow(z, aspect="auto", extent=extent, interpolation="nearest", cmap="viridis")
        bar = ax.figure.colorbar(im, ax=ax, pad=0.01, fraction=0.03)
        bar.set_label(pretty_units(p.units), fontsize=8)
    ax.set_ylabel("channel", fontsize=8)
    _heatmap_rows(ax, p, labelled=bool(s.spec.labels))
    note = f"; each cell the mean of {env.per_point} samples" if env.per_point > 1 else ""
    note += _missing(ax, env, p.channels)
    unit = pretty_units(p.units)
    ax.set_title(
        f"{s.name} — heat map of {len(p.channels)} channels, colour in {unit}{_rate_text(s)}{note}", **TITLE
    )


def _draw_steps(ax: Any, p: Panel, t0: float, t1: float) -> None:
    s = p.source
    cats = list(s.spec.categories or ())
    i, j = index_range(s, t0, t1)
    steps = change_points(s, i, j)
    if steps is None:  # changes too often for steps: the envelope, said so
        env = sample_envelope(s, i, j)
        ax.plot(env.t, env.y[:, 0], linewidth=0.6, color="C0")
        how = "min–max envelope (changes too often for steps)"
    else:
        t, v = steps
        if len(t):
            last = float(s.t[j - 1]) if j > i else t1
            ax.step(np.r_[t, last], np.r_[v, v[-1]], where="post", color="C0", linewidth=1.2)
        how = f"steps, {_count(max(len(t) - 1, 0), 'change')}" if len(t) else "no samples"
        if not len(t):
            _say(ax, "no samples in this time range")
    ax.set_yticks(range(len(cats)), cats, fontsize=8)
    ax.set_ylim(-0.5, len(cats) - 0.5)
    ax.set_title(f"{s.name} — categorical ({' / '.join(cats)}): {how}", **TITLE)


def _draw_raster(ax: Any, p: Panel, t0: float, t1: float) -> None:
    s = p.source
    spec = s.spec
    n = n_event_units(spec)
    col = _event_columns(spec).get("unit", 0) if s.data.ndim > 1 else None
    i, j = index_range(s, t0, t1)
    what = p.what or "events"
    if j - i <= MAX_EVENT_TICKS:
        t, d = event_points(s, i, j)
        unit = d if col is None else d[:, col]
        ax.plot(
            t, unit, linestyle="none", marker="|", markersize=float(np.clip(90.0 / n, 2.0, 10.0)), color="k"
        )
        how = ""
        if j == i:
            _say(ax, f"no {what} in this time range")
    else:  # too many for a tick each: counts per (unit, bin), bounded
        edges = np.linspace(t0, t1, 1001)
        counts = binned_event_counts(s, i, j, n, edges, col)
        top = max(float(counts.max()), 1.0)
        ax.imshow(
            counts.T,
            aspect="auto",
            extent=(t0, t1, n - 0.5, -0.5),
            cmap="Greys",
            interpolation="nearest",
            vmin=0.0,
            vmax=top,
        )
        how = f" as counts per {_ms(edges[1] - edges[0])} bin (white 0, black {top:g})"
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_ylabel("channel" if what == "pulses" else "unit", fontsize=8)
    labels = spec.labels if col is None else None
    if labels and len(labels) == n and n <= 24:
        ax.set_yticks(range(n), list(labels))
    elif n <= 8:
        ax.set_yticks(range(n))
    rows = _count(n, "channel" if what == "pulses" else "unit")
    ax.set_title(f"{s.name} — {what[:-1]} raster{how}: {_count(j - i, what[:-1])} on {rows}", **TITLE)


def _draw_rate(ax: Any, p: Panel, t0: float, t1: float) -> None:
    s = p.source
    n = n_event_units(s.spec)
    rate = "firing rate" if event_word(s.name) == "spikes" else "event rate"
    i, j = index_range(s, t0, t1)
    edges, bin_s = _rate_edges(t0, t1)
    rates = binned_event_counts(s, i, j, n, edges) / bin_s
    if n <= MAX_RATE_LINES:
        labels = (
            list(s.spec.labels)
            if s.spec.labels and len(s.spec.labels) == n
            else [f"unit {k}" for k in range(n)]
        )
        for k in range(n):
            ax.stairs(rates[:, k], edges, label=labels[k], linewidth=1.0)
        _legend(ax, n)
        what = f"{rate} per unit"
    else:
        ax.stairs(rates.mean(axis=1), edges, linewidth=1.0, color="C3")
        what = f"population {rate} (mean over {n} units)"
    ax.set_ylabel("1/s", fontsize=8)
    ax.set_ylim(bottom=0)
    ax.set_title(f"{s.name} — {what}, {_ms(bin_s)} bins", **TITLE)


def _draw_pulses(ax: Any, p: Panel, t0: float, t1: float) -> None:
    s = p.source
    cols = _event_columns(s.spec)
    labels = list(s.spec.labels or ())
    amp_name, amp_unit = label_unit(labels[cols["amplitude"]])
    amp_unit = pretty_units(amp_unit or s.spec.units)
    i, j = index_range(s, t0, t1)
    n = max(s.spec.n_units or 1, 1)
    widths = ""
    if j - i <= MAX_EVENT_TICKS:
        t, d = event_points(s, i, j)
        amp = d[:, cols["amplitude"]]
        unit = d[:, cols.get("unit", 0)].astype(int)
        if n <= MAX_RATE_LINES:
            for k in range(n):
                m = unit == k
                ax.vlines(t[m], 0, amp[m], color=f"C{k % 10}", linewidth=0.8, label=f"channel {k}")
            _legend(ax, n)
        else:
            ax.vlines(t, 0, amp, color="C3", linewidth=0.6)
        how = f"{_count(j - i, 'pulse')} on {n} channels"
        if j == i:
            _say(ax, "no pulses in this time range")
        if "width" in cols and len(d):
            w = d[:, cols["width"]]
            w_unit = pretty_units(label_unit(labels[cols["width"]])[1] or s.spec.units)
            span = f"{w.min():g}" if w.min() == w.max() else f"{w.min():g}–{w.max():g}"
            widths = f"; widths {span} {w_unit} (not to scale)"
    else:
        how = f"{_count(j - i, 'pulse')}: too many to draw one by one, see the raster below"
    ax.set_ylabel(amp_unit, fontsize=8)
    ax.set_ylim(bottom=0)
    ax.set_title(f"{s.name} — stimulation pulses: {amp_name} per pulse, {how}{widths}", **TITLE)


_DRAW = {
    "lines": _draw_lines,
    "heatmap": _draw_heatmap,
    "steps": _draw_steps,
    "raster": _draw_raster,
    "rate": _draw_rate,
    "pulses": _draw_pulses,
}


def draw_panel(ax: Any, p: Panel, t0: float, t1: float) -> None:
    """Draw a time-axis panel (every kind but frames) on ``ax``."""
    _DRAW[p.kind](ax, p, t0, t1)
    ax.grid(True, alpha=0.25, linewidth=0.5)
    ax.tick_params(labelsize=8)


def _cameras(frames: np.ndarray) -> tuple[np.ndarray, bool]:
    """Frames as (k, cameras, H, W[, 3|4]) and whether they are colour."""
    shape = frames.shape[1:]
    colour = len(shape) >= 3 and shape[-1] in (3, 4) and shape[-2] >= 8 and frames.dtype == np.uint8
    img = shape[-3:] if colour else shape[-2:]
    return frames.reshape(len(frames), -1, *img), colour


def draw_frames(subfig: Any, p: Panel, t0: float, t1: float) -> None:
    """A strip of thumbnails at evenly spaced times (rows: cameras) on a subfigure, times on top."""
    s = p.source
    i, j = index_range(s, t0, t1)
    count = min(THUMBNAILS, j - i)
    if count <= 0:
        ax = subfig.add_subplot()
        ax.set_axis_off()
        ax.set_title(f"{s.name} — no frames between {t0:g} s and {t1:g} s", **TITLE)
        return
    first, last = float(s.t[i]), float(s.t[j - 1])
    times, frames = frames_at(s, np.linspace(first, last, count))
    imgs, colour = _cameras(frames)
    n_cam = imgs.shape[1]
    if frames.dtype == np.uint8:
        lo, hi, scale = 0, 255, f"gray 0–255 {pretty_units(s.spec.units)}"
    else:
        finite = imgs[np.isfinite(imgs)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        scale = f"gray {lo:.3g}–{hi:.3g} {pretty_units(s.spec.units)}" + ("" if finite.size else " (all NaN)")
    axes = subfig.subplots(n_cam, len(times), squeeze=False)
    for c, (k, t) in itertools.product(range(n_cam), enumerate(times)):
        ax = axes[c, k]
        ax.imshow(imgs[k, c], cmap=None if colour else "gray", vmin=lo, vmax=hi, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        if c == 0:
            ax.set_title(f"t = {t:.3f} s", fontsize=7)
        if k == 0 and n_cam > 1:
            ax.set_ylabel(f"camera {c}", fontsize=7)
    cams = f", {n_cam} cameras" if n_cam > 1 else ""
    shape = "×".join(map(str, s.spec.shape))
    subfig.suptitle(
        f"{s.name} — {len(times)} of {s.n} frames ({shape}) at evenly spaced times{cams}; {scale}",
        x=0.01,
        ha="left",
        fontsize=9,
    )
