"""graphs/touchsim_afferents.yaml: TouchSim's own s, d fed in reproduce TouchSim's current (noise off)."""

from pathlib import Path

import numpy as np
import pytest
from touchsim_dev import EPS, prefilter_bound, touchsim_traces

from flowtact.graphfile.graph import load_graph
from flowtact.testing import run_graph

pytest.importorskip("scipy.signal")

GRAPH = Path(__file__).parents[3] / "graphs" / "touchsim_afferents.yaml"
COLUMNS = ("SA1|0", "RA|0", "PC|0")  # the graph's afferents, in column order


@pytest.mark.oracle
@pytest.mark.parametrize("stim", ["ramp03", "sine100", "noise7"])
def test_the_graph_reproduces_touchsims_current_from_its_s_and_d(stim):
    """Deliver 4: s, d → prefilter → gains in the shipped graph (its p values, its wiring) give the
    development set's I for its three afferents, within the stage tests' derived bounds."""
    traces = dict(touchsim_traces())
    cols = [traces[f"{stim}|{c}"] for c in COLUMNS]
    n = len(cols[0]["s"])
    t = np.arange(n) / 5000.0
    s = np.stack([tr["s"] for tr in cols], axis=1)
    d = np.stack([tr["d"] for tr in cols], axis=1)
    out = run_graph(GRAPH, overrides=["current.noise_sd=[0.0]"], feed={"probe.s": (t, s), "probe.d": (t, d)})
    y = out["current.y"]
    np.testing.assert_array_equal(y.t, t)  # every sample, the last one (Δd = 0) included
    for j, (c, tr) in enumerate(zip(COLUMNS, cols, strict=True)):
        tol = 16 * EPS * (np.abs(tr["I"]).max() + 1.0) * 8 + prefilter_bound(f"{stim}|{c}", tr)
        assert np.abs(y.data[:, j] - tr["I"]).max() <= tol, c


def test_the_graph_holds_the_parameters_of_its_three_models():
    """The p values written in the graph are those of touchsim_params.npz (no typo in 27 numbers)."""
    traces = dict(touchsim_traces())
    nodes = load_graph(GRAPH).nodes
    cur, pre = nodes["current"].config, nodes["prefilter_d"].config
    for j, c in enumerate(COLUMNS):
        p = traces[f"ramp03|{c}"]["p"]
        got = [pre.cutoff_hz[j] / 10, cur.pos1[j], cur.neg1[j], cur.pos2[j], cur.neg2[j], cur.ahead_pos[j],
               cur.ahead_neg[j], cur.saturation[j], cur.noise_sd[j]]  # fmt: skip
        np.testing.assert_allclose(got, p[:9], rtol=4 * EPS, atol=0)
    assert nodes["prefilter_s"].config.cutoff_hz == pre.cutoff_hz


@pytest.mark.oracle
def test_every_dev_trace_spikes_as_touchsim_from_s_and_d_through_the_whole_chain(tmp_path):
    """Done means (issue 33): all 68 development traces, from TouchSim's s and d through prefilter,
    rectified weighting and the afferent (noise off), fire TouchSim's spikes on the same samples —
    one 68-unit population mixing the 17 models, as the shipped graph wires them."""
    traces = touchsim_traces()
    n = len(traces[0][1]["s"])
    assert all(len(tr["s"]) == n for _, tr in traces)
    p = np.array([tr["p"] for _, tr in traces])
    models = [".".join(key.split("|")[1:]) for key, _ in traces]  # STIM|SA1|0 -> SA1.0
    probe = next(line for line in GRAPH.read_text().splitlines() if line.lstrip().startswith("probe:"))
    doc = GRAPH.read_text().replace(
        probe, f"  probe: {{block: touchsim_probe, params: {{n: {len(traces)}}}}}"
    )
    params = {
        "pos1": p[:, 1], "neg1": p[:, 2], "pos2": p[:, 3], "neg2": p[:, 4],
        "ahead_pos": p[:, 5], "ahead_neg": p[:, 6], "saturation": p[:, 7],
    }  # fmt: skip
    overrides = ["current.noise_sd=[0.0]"]
    overrides += [f"afferents.models={models}"]
    overrides += [f"prefilter_{x}.cutoff_hz={(10 * p[:, 0]).tolist()}" for x in "sd"]
    overrides += [f"current.{k}={v.tolist()}" for k, v in params.items()]
    path = tmp_path / "chain.yaml"
    path.write_text(doc)
    t = np.arange(n) / 5000.0
    s = np.stack([tr["s"] for _, tr in traces], axis=1)
    d = np.stack([tr["d"] for _, tr in traces], axis=1)
    out = run_graph(path, overrides=overrides, feed={"probe.s": (t, s), "probe.d": (t, d)})
    spikes = out["afferents.spikes"]
    samples = np.rint(spikes.t * 5000.0).astype(np.int64)
    for j, (key, tr) in enumerate(traces):
        np.testing.assert_array_equal(samples[spikes.data == j], tr["spk"], err_msg=key)
