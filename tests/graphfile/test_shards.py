"""``shards: K``: a population split over processes records exactly what the unsharded one does."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from flowtact.errors import GraphFileError
from flowtact.graphfile.graph import load_graph
from flowtact.graphfile.shards import ShardSlice, shard_bounds
from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled
from flowtact.runtime.placement import place
from flowtact.testing import CHECKS, run_graph

ROOT = Path(__file__).parents[2]


def _graph(tmp_path: Path, name: str, nodes: dict, edges: list, record: list, shards: dict) -> Path:
    doc = {"name": name, "seed": 5, "duration_s": 0.1, "nodes": nodes, "edges": edges, "record": record}
    for node, k in shards.items():
        doc["nodes"][node] = {**doc["nodes"][node], "shards": k}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _noisy_population(tmp_path: Path, k: int, n: int = 5000, name: str = "pop") -> Path:
    """A ramp into a noisy nlif of n units (5000: two noise streams, 4096 + 904)."""
    gain = [60.0 + 140.0 * i / n for i in range(n)]
    nodes = {
        "probe": {"block": "touchsim_probe", "params": {"n": n, "onset_s": 0.0, "ramp_s": 0.02}},
        "pop": {"block": "nlif", "params": {"n": n, "gain": gain, "tau_s": 0.01, "sigma": 3.0}},
    }
    return _graph(tmp_path, f"{name}{k}", nodes, ["probe.s -> pop.x"], ["pop.spikes"], {"pop": k})


def _same(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for name in a:
        assert len(a[name].t) > 0, name
        np.testing.assert_array_equal(a[name].t, b[name].t, err_msg=name)
        np.testing.assert_array_equal(a[name].data, b[name].data, err_msg=name)


def test_a_noisy_population_in_two_shards_records_the_same_spikes_bit_for_bit(tmp_path):
    """Deliver 3: every unit's noise is the same sharded or not (the cut falls on its noise streams'
    boundary, shard 1 starts at stream 1), and the merge renumbers and orders spikes as one
    population does. Without nlif's noise_offset, shard 1 drew stream 0's normals: checked to fail."""
    one = run_graph(_noisy_population(tmp_path, 1))
    two = run_graph(_noisy_population(tmp_path, 2))
    _same(one, two)
    units = one["pop.spikes"].data
    assert units.min() < 4096 <= units.max()  # both shards fire


def test_the_whole_touchsim_chain_sharded_alike_joins_shard_to_shard_and_stays_bit_identical(tmp_path):
    """Probe → prefilters → noisy current (rectified_gain) → TouchSim models (per-unit kernel), each
    node in 2 shards: one process per shard (no merge or slice inside the chain) and the spikes and
    current are those of the unsharded chain, noise included."""
    n = 4200
    models = [["SA1.0", "RA.3", "PC.1", "RA.0", "SA1.2"][i % 5] for i in range(n)]
    nodes = {
        "probe": {
            "block": "touchsim_probe",
            "params": {"n": n, "s_peak": [0.02], "d_peak": [4.0], "onset_s": 0.0},
        },
        "pre": {
            "block": "iir",
            "params": {"family": "butter", "order": 3, "cutoff_hz": [100.0 + i % 7 for i in range(n)]},
        },
        "current": {
            "block": "rectified_gain",
            "params": {"pos1": [1.0 + (i % 3) for i in range(n)], "noise_sd": [0.05], "saturation": [0.0]},
        },
        "aff": {"block": "nlif", "params": {"models": models}},
    }
    edges = ["probe.s -> pre.x", "pre.y -> current.x1", "current.y -> aff.x"]
    record = ["aff.spikes", "current.y"]
    both = {
        k: _graph(tmp_path, f"chain{k}", dict(nodes), edges, record, dict.fromkeys(nodes, k)) for k in (1, 2)
    }
    plan = load_compiled(both[2])
    assert {n for n in plan.graph.nodes if "__in_" in n} == set()  # shard to shard
    assert set(place(plan, fast=True).groups) == {"probe_s0", "probe_s1"}
    one, two = run_graph(both[1]), run_graph(both[2])
    _same(one, two)
    assert two["current.y"].data.shape[1] == n


def test_across_processes_a_sharded_population_equals_the_unsharded_one_in_process(tmp_path):
    """Deliver 3 in the multi-process runtime: the shards really run in two workers and the
    recording is the in-process unsharded one's, bit for bit."""
    plan = load_compiled(_noisy_population(tmp_path, 2))
    assert set(place(plan, fast=True).groups) == {"main", "pop_s0", "pop_s1"}
    run_compiled(plan, fast=True, record=tmp_path / "procs.h5")
    run_compiled(
        load_compiled(_noisy_population(tmp_path, 1)), fast=True, inproc=True, record=tmp_path / "one.h5"
    )
    a, b = read_recording(tmp_path / "one.h5"), read_recording(tmp_path / "procs.h5")
    assert set(a.streams) == set(b.streams) == {"pop.spikes"}
    x, y = a.streams["pop.spikes"], b.streams["pop.spikes"]
    assert len(x.t) > 0
    assert np.array_equal(x.t, y.t) and np.array_equal(x.data, y.data)
    assert b.streams["pop.spikes"].spec.n_units == 5000


def test_sample_outputs_are_joined_column_wise_and_the_node_keeps_its_name(tmp_path):
    """A noise-free population cuts anywhere (3 shards of 7 units: 2, 3, 2); its membrane v is the
    unsharded v, its spikes carry the whole population's unit numbers, named 'pop.*'."""
    nodes = {
        "probe": {"block": "touchsim_probe", "params": {"n": 7, "onset_s": 0.0, "ramp_s": 0.02}},
        "pop": {
            "block": "nlif",
            "params": {"n": 7, "gain": [40.0 * (i + 1) for i in range(7)], "tau_s": 0.01},
        },
    }
    rec = ["pop.spikes", "pop.v"]
    one = run_graph(_graph(tmp_path, "v1", nodes, ["probe.s -> pop.x"], rec, {}))
    three = run_graph(_graph(tmp_path, "v3", nodes, ["probe.s -> pop.x"], rec, {"pop": 3}))
    _same(one, three)
    assert set(one["pop.spikes"].data) == set(range(1, 7))  # units of every shard fire (0 is too weak)


def test_bounds_are_even_on_the_alignment_and_refuse_what_cannot_be_split():
    assert shard_bounds(7, 3, 1) == [0, 2, 5, 7]
    assert shard_bounds(16900, 2, 4096) == [0, 8192, 16900]
    assert shard_bounds(5000, 2, 4096) == [0, 4096, 5000]
    assert "more than its 3 units" in shard_bounds(3, 4, 1)
    assert "use at most 2 shards" in shard_bounds(5000, 3, 4096)


@pytest.mark.parametrize(
    ("node", "message"),
    [
        ({"block": "rate", "params": {}, "shards": 2}, "block 'rate' cannot be sharded"),
        ({"block": "nlif", "params": {"n": 3}, "shards": 4}, "shards: 4 is more than its 3 units"),
        ({"block": "nlif", "params": {"n": 10, "sigma": 1.0}, "shards": 2}, "blocks of 4096 units"),
        ({"block": "nlif", "params": {"n": 4}, "shards": 0}, "'shards' must be an integer from 1 to 16"),
        ({"block": "nlif", "params": {"n": 4}, "shards": 2, "process": ["a"]}, "lists 1 groups for 2"),
    ],
    ids=["not-shardable", "too-many", "noise-alignment", "zero", "process-list"],
)
def test_bad_shards_are_one_located_error(tmp_path, node, message):
    """Deliver 3's errors: each names the file, line and column of the node's ``shards:``."""
    doc = {
        "name": "bad",
        "nodes": {"probe": {"block": "touchsim_probe", "params": {"n": 4}}, "pop": node},
        "edges": ["probe.s -> pop.x"] if node["block"] == "nlif" else ["probe.s -> pop.spikes"],
    }
    if node["block"] == "rate":
        doc["nodes"]["src"] = {"block": "nlif", "params": {"n": 4}}
        doc["edges"] = ["probe.s -> src.x", "src.spikes -> pop.spikes"]
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(GraphFileError) as e:
        load_graph(path)
    text = str(e.value)
    assert message in text, text
    assert f"{path}:" in text and "shards" in text


def test_process_list_names_each_shards_group(tmp_path):
    nodes = {
        "probe": {"block": "touchsim_probe", "params": {"n": 6}},
        "pop": {"block": "nlif", "params": {"n": 6}, "process": ["left", "right"]},
    }
    plan = load_compiled(_graph(tmp_path, "named", nodes, ["probe.s -> pop.x"], ["pop.spikes"], {"pop": 2}))
    groups = place(plan, fast=True).group_of
    assert (groups["pop__s0"], groups["pop__s1"]) == ("left", "right")


def test_the_hand_graph_is_16900_afferents_in_two_processes():
    """graphs/hand.yaml: TouchSim's class counts from its densities, 2 shards, one process each."""
    plan = load_compiled(ROOT / "graphs" / "hand.yaml")
    assert plan.specs[("afferents", "spikes")].n_units == 16900
    assert set(place(plan, fast=True).groups) == {"probe_s0", "probe_s1"}
    nodes = plan.graph.nodes
    assert len(nodes["afferents__s0"].config.models) == 8192
    assert nodes["afferents__s1"].config.noise_offset == 8192


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_the_slice_block_conforms(check):
    check(ShardSlice)


def test_a_processes_section_may_configure_the_shards_groups(tmp_path):
    """A shard's group (named in the process list, or <node>_s<k>) takes `processes:` settings."""
    nodes = {
        "probe": {"block": "touchsim_probe", "params": {"n": 6}},
        "pop": {"block": "nlif", "params": {"n": 6}},
    }
    path = _graph(tmp_path, "groups", nodes, ["probe.s -> pop.x"], ["pop.spikes"], {"pop": 2})
    doc = yaml.safe_load(path.read_text())
    doc["processes"] = {"pop_s1": {"restart": "on-failure"}}
    path.write_text(yaml.safe_dump(doc))
    plan = load_compiled(path)
    assert place(plan, fast=True).processes["pop_s1"].restart == "on-failure"


def test_a_deadline_from_a_sharded_source_is_one_deadline_per_shard(tmp_path):
    """The runtime stamps latency at sources: `from: probe` on a sharded probe must become a path
    from each shard (else no worker measures it: issue 33's p99 lateness of the whole hand)."""
    nodes = {
        "probe": {"block": "touchsim_probe", "params": {"n": 6}},
        "pop": {"block": "nlif", "params": {"n": 6}},
    }
    path = _graph(tmp_path, "late", nodes, ["probe.s -> pop.x"], ["pop.spikes"], {"probe": 2, "pop": 2})
    doc = yaml.safe_load(path.read_text())
    doc["deadlines"] = [{"from": "probe", "to": "pop", "budget": "5ms"}]
    path.write_text(yaml.safe_dump(doc))
    paths = [(d.src, d.dst) for d in load_graph(path).deployment.deadlines]
    assert paths == [("probe__s0", "pop"), ("probe__s1", "pop")]
    where = place(load_compiled(path), fast=False)
    plans = [where.worker_plan(g, fast=False, tick_s=0.005, duration_s=1.0) for g in where.groups]
    assert {d.name for p in plans for d in p.deadlines} == {"probe__s0 -> pop", "probe__s1 -> pop"}
