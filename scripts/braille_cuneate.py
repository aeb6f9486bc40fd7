"""Why the second-order (cuneate) layer of the Braille pathway reads worse than the afferents.

Runs graphs/braille_open.yaml in process (``reading.read_line``) for the training text (graph seeds
1-3 at 15, 30 and 60 mm/s, 260 letters each: the recipe of ``flowtact train-braille``) and for a
validation text (graph seeds 600 + k, one per speed: neither training nor the benchmark's held-out
seeds from 100 000, so nothing here is tuned on held-out text). The afferent spikes of each run
are then fed, offline, through the same ``synapse`` and ``nlif`` blocks the graph uses, once per
variant of the second-order layer (one factor changed at a time from the preset): every variant
sees exactly the same afferent spikes, so the differences are the layer's alone.

For every variant and layer it reports the decoder's recognition rate per validation speed (the
shipped decoder: multinomial naive Bayes on spike counts in 2 time-normalised sub-bins, trained on
the training text) and the information the counts carry about the letter (``braille_metrics.
mi_corrected``, a cross-validated decoder's confusion matrix, bias removed) at 30 and 80 mm/s.
Decoder variants (sub-bins, a logistic regression that does not assume independent units) are
run on the same features.

    python scripts/braille_cuneate.py                       # the table in docs/braille.md, ~3 min
    python scripts/braille_cuneate.py --figure cuneate.png  # and its figure
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flowtact.bench.braille_metrics import mi_corrected
from flowtact.blocks.braille.cells import LETTERS
from flowtact.blocks.braille.presets import CUNEATE, CUNEATE_SYNAPSE
from flowtact.blocks.braille.reading import Reading, read_line
from flowtact.blocks.spiking.nb_model import fit_multinomial, log_posterior
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.spiking.synapse import Synapse, SynapseConfig
from flowtact.blocks.spiking.window_features import window_features
from flowtact.chunk import StreamSpec
from flowtact.testing import run_offline

TRAIN_SPEEDS = (15.0, 30.0, 60.0)
TRAIN_SEED = 1
VALID_SEED = 600
SPEEDS = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0, 150.0, 200.0)
MI_SPEEDS = (30.0, 80.0)
#: The decoder without the independence assumption (slow) runs on these layers and speeds only.
LOGREG_SPEEDS = (30.0, 80.0, 200.0)
DECODER_LAYERS = ("first order", "old preset", "shipped preset")
#: Speeds above the scan's default limit (100 mm/s) run with it raised to this.
FAST_LIMIT_MM_S = 400.0
#: The shipped values before the secure-relay preset (the variants below change one of them at a time).
OLD_SYNAPSE: dict[str, Any] = {
    "rate_hz": 250.0, "tau_s": 0.01, "grid": (6, 4), "n_targets": 49, "fan_in": (1, 3), "weight": 1.0,
    "connect_seed": 13,
}  # fmt: skip
OLD_NLIF: dict[str, Any] = {
    "n": 49, "tau_s": 0.01, "v_leak": 0.0, "gain": 1.0, "sigma": 1.0, "refractory_s": 0.008, "integrator": "exp",
}  # fmt: skip


@dataclass(frozen=True)
class Variant:
    """A second-order layer: overrides of the old synapse and nlif parameters."""

    name: str
    synapse: Mapping[str, Any] = field(default_factory=dict)
    nlif: Mapping[str, Any] = field(default_factory=dict)

    def params(self) -> tuple[dict[str, Any], dict[str, Any]]:
        return {**OLD_SYNAPSE, **self.synapse}, {**OLD_NLIF, **self.nlif}


VARIANTS = (
    Variant("old preset"),
    Variant("connect_seed 1", synapse={"connect_seed": 1}),
    Variant("connect_seed 2", synapse={"connect_seed": 2}),
    Variant("fan-in 1 (relay)", synapse={"fan_in": (1, 1)}),
    Variant("fan-in 3", synapse={"fan_in": (3, 3)}),
    Variant("fan-in 2-5", synapse={"fan_in": (2, 5)}),
    Variant("tau_syn 4 ms", synapse={"tau_s": 0.004}),
    Variant("tau_syn 2 ms", synapse={"tau_s": 0.002}),
    Variant("gain 2", nlif={"gain": 2.0}),
    Variant("gain 4", nlif={"gain": 4.0}),
    Variant("sigma 0", nlif={"sigma": 0.0}),
    Variant("refractory 4 ms", nlif={"refractory_s": 0.004}),
    Variant("tau_m 4 ms", nlif={"tau_s": 0.004}),
    Variant("tau_m 2 ms", nlif={"tau_s": 0.002}),
    Variant("gain 3", nlif={"gain": 3.0}),
    Variant("gain 4, refractory 4 ms", nlif={"gain": 4.0, "refractory_s": 0.004}),
    Variant("gain 2, tau_m 4 ms", nlif={"gain": 2.0, "tau_s": 0.004}),
    Variant("gain 1.5, tau_m 4 ms", nlif={"gain": 1.5, "tau_s": 0.004}),
    Variant("gain 3, tau_m 4 ms", nlif={"gain": 3.0, "tau_s": 0.004}),
    Variant("gain 2, tau_syn 4 ms", synapse={"tau_s": 0.004}, nlif={"gain": 2.0}),
    Variant("gain 4, tau_syn 4 ms", synapse={"tau_s": 0.004}, nlif={"gain": 4.0}),
    Variant("gain 3, tau_syn 4 ms", synapse={"tau_s": 0.004}, nlif={"gain": 3.0}),
    Variant("gain 4, tau_syn 4 ms, tau_m 4 ms", synapse={"tau_s": 0.004}, nlif={"gain": 4.0, "tau_s": 0.004}),
    Variant("shipped preset", synapse=dict(CUNEATE_SYNAPSE), nlif=dict(CUNEATE)),
)
VARIANT_NAMES = tuple(v.name for v in VARIANTS)


def second_order(r: Reading, variant: Variant, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The variant's cuneate spikes for the afferent spikes of run ``r`` (the graph's blocks, offline)."""
    syn_p, nlif_p = variant.params()
    t, u = r.spikes["first"]
    spec = {"spikes": StreamSpec("int64", (), "1", r.rate_hz, events=True, n_units=r.n_units["first"])}
    y = run_offline(Synapse(**syn_p), specs=spec, spikes=(t, u))["y"]
    n = round(r.duration_s * r.rate_hz)  # the graph's synapse runs to the end of the line: its tail decays
    tail = n - len(y)
    decay = np.exp(-1.0 / (r.rate_hz * syn_p["tau_s"]))
    last = y.data[-1] if len(y) else np.zeros(syn_p["n_targets"])
    x = np.vstack([y.data, last * decay ** np.arange(1, tail + 1)[:, None]]) if tail > 0 else y.data
    s = run_offline(Nlif(**nlif_p), x=x, t=np.arange(len(x)) / r.rate_hz, rate_hz=r.rate_hz, seed=seed)
    return s["spikes"].t, np.asarray(s["spikes"].data, np.int64)


def features(spikes: tuple[np.ndarray, np.ndarray], r: Reading, n_units: int, n_bins: int) -> np.ndarray:
    return window_features(*spikes, r.windows, n_units=n_units, n_bins=n_bins)


def letters_only(r: Reading) -> Reading:
    """The run with only the windows labelled a letter (a reader whose windows come from the finger's
    position may also cut windows over gaps or spaces)."""
    keep = [i for i, c in enumerate(r.letters) if c in LETTERS]
    return dataclasses.replace(r, windows=r.windows[keep], letters=tuple(r.letters[i] for i in keep))


def labels(r: Reading) -> np.ndarray:
    return np.array([LETTERS.index(c) for c in r.letters], np.int64)


def nb_accuracy(xtr: np.ndarray, ytr: np.ndarray, xte: np.ndarray, yte: np.ndarray, n_bins: int) -> float:
    """The shipped decoder's recognition rate: multinomial naive Bayes, alpha 1."""
    names = list(LETTERS)
    m = fit_multinomial(
        xtr, [names[i] for i in ytr], names, n_units=xtr.shape[1] // n_bins, n_bins=n_bins, alpha=1.0
    )
    return float(np.mean(np.argmax(log_posterior(m, xte), axis=1) == yte))


def logreg_accuracy(xtr: np.ndarray, ytr: np.ndarray, xte: np.ndarray, yte: np.ndarray) -> float:
    """A decoder without the independence assumption (scikit-learn, a dev dependency)."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    clf = make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=500))
    clf.fit(np.log1p(xtr), ytr)
    return float(np.mean(clf.predict(np.log1p(xte)) == yte))


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--letters", type=int, default=520, help="validation letters per speed (default 520)")
    ap.add_argument("--train-letters", type=int, default=260, help="training letters per speed (260)")
    ap.add_argument("--variants", default="", help="variant names separated by semicolons (default: all)")
    ap.add_argument("--json", default="", help="write the results to this JSON file")
    ap.add_argument("--figure", default="", help="draw the figure to this PNG file")
    ap.add_argument("--from-json", default="", help="only draw --figure from a --json file written before")
    a = ap.parse_args(argv)
    if a.from_json:
        with open(a.from_json) as f:
            draw(json.load(f), a.figure)
        return 0
    variants = [v for v in VARIANTS if not a.variants or v.name in a.variants.split(";")]
    t_start = time.time()
    train = [
        letters_only(read_line(seed=TRAIN_SEED + k, speed_mm_s=s, letters=a.train_letters, layers=("first",)))
        for k, s in enumerate(TRAIN_SPEEDS)
    ]
    valid = {
        s: letters_only(
            read_line(
                seed=VALID_SEED + k,
                speed_mm_s=s,
                letters=a.letters,
                layers=("first",),
                params={"scan": {"max_speed_mm_s": FAST_LIMIT_MM_S}} if s > 100 else None,
            )
        )
        for k, s in enumerate(SPEEDS)
    }
    print(f"simulated in {time.time() - t_start:.0f} s", file=sys.stderr)
    ytr = np.concatenate([labels(r) for r in train])
    results: dict[str, Any] = {"speeds": SPEEDS, "mi_speeds": MI_SPEEDS, "layers": {}}

    def evaluate(name: str, spikes_of: Any, n_units: int) -> dict[str, Any]:
        out: dict[str, Any] = {
            "nb2": {},
            "nb1": {},
            "nb4": {},
            "logreg2": {},
            "mi1": {},
            "mi2": {},
            "rate": {},
        }
        tr = {
            b: np.vstack([features(spikes_of(r, i), r, n_units, b) for i, r in enumerate(train)])
            for b in (1, 2, 4)
        }
        for k, s in enumerate(SPEEDS):
            r = valid[s]
            sp = spikes_of(r, 100 + k)
            yte = labels(r)
            for b in (1, 2, 4):
                x = features(sp, r, n_units, b)
                out[f"nb{b}"][s] = nb_accuracy(tr[b], ytr, x, yte, b)
                if b == 2 and s in LOGREG_SPEEDS and name in DECODER_LAYERS:
                    out["logreg2"][s] = logreg_accuracy(tr[2], ytr, x, yte)
                if b == 1:
                    out["rate"][s] = float(x.mean())
                if s in MI_SPEEDS and b in (1, 2):
                    out[f"mi{b}"][s] = mi_corrected(x, yte, len(LETTERS), folds=5, seed=0)[0]
        print(
            f"{name:18s} NB2 " + " ".join(f"{out['nb2'][s]:6.1%}" for s in SPEEDS)
            + " | MI1 " + " ".join(f"{out['mi1'][s]:.2f}" for s in MI_SPEEDS)
            + " MI2 " + " ".join(f"{out['mi2'][s]:.2f}" for s in MI_SPEEDS)
            + f" | spikes/unit/window {out['rate'][30.0]:.2f}",
            flush=True,
        )  # fmt: skip
        return out

    print(f"{'':18s} NB2 " + " ".join(f"{s:>6g}" for s in SPEEDS) + " mm/s")
    results["layers"]["first order"] = evaluate("first order", lambda r, _i: r.spikes["first"], 24)
    for v in variants:
        results["layers"][v.name] = evaluate(v.name, lambda r, i, v=v: second_order(r, v, i), 49)
    results["transfer"] = {
        v.name: transfer(valid[TRANSFER_SPEED], v)
        for v in variants
        if v.name in ("old preset", "shipped preset")
    }
    print(f"total {time.time() - t_start:.0f} s", file=sys.stderr)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1, default=str)
    if a.figure:
        draw(results, a.figure)
    return 0


TRANSFER_SPEED = 80.0


def transfer(r: Reading, variant: Variant) -> dict[str, list[float]]:
    """Spike transfer through the cuneate neurons that sample one afferent: for each afferent count
    n in a window, the mean count of those neurons and the fraction of them silent."""
    syn_p, _ = variant.params()
    w = SynapseConfig(**syn_p).matrix()
    single = np.flatnonzero((w != 0).sum(axis=1) == 1)
    src = np.argmax(w[single] != 0, axis=1)
    aff = window_features(*r.spikes["first"], r.windows, n_units=24)[:, src].ravel()
    cun = window_features(*second_order(r, variant, 0), r.windows, n_units=49)[:, single].ravel()
    out: dict[str, list[float]] = {"n": [], "mean": [], "silent": [], "windows": []}
    for n in range(int(aff.max()) + 1):
        sel = aff == n
        if sel.sum() >= 20:
            out["n"].append(n)
            out["mean"].append(float(cun[sel].mean()))
            out["silent"].append(float((cun[sel] == 0).mean()))
            out["windows"].append(int(sel.sum()))
    return out


def draw(results: Mapping[str, Any], path: str) -> None:
    """Recognition against speed; each factor's information at 80 mm/s; spike transfer."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lay = results["layers"]
    speeds = [float(s) for s in results["speeds"]]
    fig, ax = plt.subplots(1, 3, figsize=(16, 7), gridspec_kw={"width_ratios": [1.0, 1.25, 1.0]})
    styles = {"first order": "k-o", "old preset": "r--s", "shipped preset": "b-^"}
    for name, st in styles.items():
        if name in lay:
            acc = lay[name]["nb2"]
            ax[0].plot(speeds, [100 * acc[_key(acc, s)] for s in speeds], st, label=name)
    ax[0].axhline(100 / len(LETTERS), color="gray", lw=0.8, ls=":", label="chance (1/26)")
    ax[0].set_xscale("log")
    ax[0].set_xticks(speeds, [f"{s:g}" for s in speeds])
    ax[0].set_xlabel("scanning speed (mm/s)")
    ax[0].set_ylabel("recognition (%), validation text")
    ax[0].set_title("decoder (NB, counts in 2 sub-bins)")
    ax[0].legend(fontsize=8)
    names = [n for n in lay if n != "first order"]
    y = np.arange(len(names))
    for k, (key, label, col) in enumerate(
        (("mi1", "whole-window counts", "C0"), ("mi2", "2 sub-bins", "C1"))
    ):
        vals = [lay[n][key][_key(lay[n][key], TRANSFER_SPEED)] for n in names]
        ax[1].barh(y + 0.2 - 0.4 * k, vals, height=0.38, color=col, label=label)
        first = lay["first order"][key][_key(lay["first order"][key], TRANSFER_SPEED)]
        ax[1].axvline(first, color=col, ls="--", lw=1)
    ax[1].set_yticks(y, names, fontsize=8)
    ax[1].invert_yaxis()
    ax[1].set_xlabel(f"information about the letter at {TRANSFER_SPEED:g} mm/s (bits; dashed: first order)")
    ax[1].set_xlim(0.0, 4.8)
    ax[1].legend(fontsize=8, loc="upper right")
    ax[1].set_title("one factor at a time (H(letter) = 4.70 bits)")
    for name, st in (("old preset", "r--s"), ("shipped preset", "b-^")):
        tr = results.get("transfer", {}).get(name)
        if tr:
            ax[2].plot(tr["n"], tr["mean"], st, label=f"{name}: mean cuneate count")
            ax[2].plot(tr["n"], tr["silent"], st[0] + ":", label=f"{name}: fraction silent")
    top = max((max(t["n"]) for t in results.get("transfer", {}).values() if t["n"]), default=6)
    ax[2].plot([0, top], [0, top], color="gray", lw=0.8, label="identity")
    ax[2].set_xlim(0, top)
    ax[2].set_ylim(0, top)
    ax[2].set_xlabel(f"spikes of the afferent in a window ({TRANSFER_SPEED:g} mm/s)")
    ax[2].set_ylabel("cuneate spikes (count), or fraction")
    ax[2].set_title("cuneate neurons sampling one afferent")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def _key(d: Mapping[Any, Any], s: float) -> Any:
    """A speed's key in a results mapping (floats, or strings once read back from JSON)."""
    return s if s in d else str(s)


if __name__ == "__main__":
    sys.exit(main())
