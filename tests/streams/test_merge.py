"""LatestMerger: pairing by time is exact and does not depend on chunk boundaries."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from flowtact.chunk import Chunk
from flowtact.streams.merge import LatestMerger


def _reference(td, to, do, initial):
    """Brute force: for each driving time, the last other sample at or before it."""
    out = []
    for t in td:
        k = np.nonzero(to <= t)[0]
        out.append(do[k[-1]] if len(k) else initial)
    return np.asarray(out, np.float64)


def _feed(merger, td, dd, to, do, cuts_d, cuts_o, end_step):
    """Feed both streams in the given pieces, interleaved, with watermarks at each piece's end."""
    got_t, got_d, got_o = [], [], []
    pieces = max(len(cuts_d), len(cuts_o)) + 1
    bd = [0, *cuts_d, len(td)]
    bo = [0, *cuts_o, len(to)]
    for i in range(pieces):
        chunks = {}
        if i < len(bd) - 1:
            a, b = bd[i], bd[i + 1]
            chunks["f"] = Chunk(td[a:b], dd[a:b])
        if i < len(bo) - 1:
            a, b = bo[i], bo[i + 1]
            # an honest watermark: never past the next sample of the stream
            end = float(to[b - 1]) + end_step if b > a else None
            if end is not None and b < len(to):
                end = min(end, float(to[b]))
            chunks["g"] = Chunk(to[a:b], do[a:b], end)
        t, d, o = merger.push(chunks)
        got_t.append(t)
        got_d.append(d)
        got_o.append(o["g"])
    t, d, o = merger.flush()
    got_t.append(t)
    got_d.append(d)
    got_o.append(o["g"])
    return np.concatenate(got_t), np.concatenate(got_d), np.concatenate(got_o)


def test_pairs_latest_sample_at_or_before():
    td = np.array([0.00, 0.01, 0.02, 0.03, 0.04])
    to = np.array([0.005, 0.025])
    m = LatestMerger("f", {"g": -1.0})
    t, d, o = m.push({"f": Chunk(td, td * 10, end=0.045), "g": Chunk(to, np.array([1.0, 2.0]))})
    # 0.03 and 0.04 wait: nothing says g has no sample in (0.025, 0.04]
    np.testing.assert_array_equal(t, [0.00, 0.01, 0.02])
    np.testing.assert_array_equal(o["g"], [-1.0, 1.0, 1.0])
    t, d, o = m.push({"g": Chunk(np.empty(0), np.empty(0), end=0.035)})
    np.testing.assert_array_equal(t, [0.03])
    np.testing.assert_array_equal(o["g"], [2.0])
    assert m.end() == 0.035  # g is known up to its watermark; 0.04 still waits
    t, d, o = m.flush()
    np.testing.assert_array_equal(t, [0.04])
    np.testing.assert_array_equal(d, [0.4])


def test_sample_at_the_same_time_counts():
    m = LatestMerger("f", {"g": 0.0})
    t, _, o = m.push(
        {"g": Chunk(np.array([0.5]), np.array([7.0])), "f": Chunk(np.array([0.5]), np.array([1.0]))}
    )
    np.testing.assert_array_equal(t, [0.5])
    np.testing.assert_array_equal(o["g"], [7.0])


@settings(max_examples=60, deadline=None)
@given(
    nd=st.integers(0, 40),
    no=st.integers(0, 25),
    seed=st.integers(0, 2**31),
    end_step=st.sampled_from([0.0, 0.001, 0.05]),
)
def test_chunking_invariant_and_exact(nd, no, seed, end_step):
    rng = np.random.default_rng(seed)
    td = np.sort(rng.uniform(0, 1, nd))
    to = np.sort(rng.uniform(0, 1, no))
    dd, do = rng.normal(size=nd), rng.normal(size=no)
    cuts_d = sorted(rng.choice(np.arange(1, nd), size=min(nd - 1, 4), replace=False)) if nd > 1 else []
    cuts_o = sorted(rng.choice(np.arange(1, no), size=min(no - 1, 4), replace=False)) if no > 1 else []
    t, d, o = _feed(LatestMerger("f", {"g": 3.0}), td, dd, to, do, cuts_d, cuts_o, end_step)
    np.testing.assert_array_equal(t, td)
    np.testing.assert_array_equal(d, dd)
    # samples released before flush saw every other sample at or before them; flushed ones too
    np.testing.assert_array_equal(o, _reference(td, to, do, 3.0))


def test_vector_streams_keep_their_shape():
    m = LatestMerger("f", {"g": np.zeros(3)}, drive_shape=(3, 2))
    _, d, o = m.push({"f": Chunk(np.empty(0), np.empty((0, 3, 2)))})
    assert d.shape == (0, 3, 2) and o["g"].shape == (0, 3)
    _, d, o = m.push(
        {
            "f": Chunk(np.array([0.1]), np.ones((1, 3, 2))),
            "g": Chunk(np.array([0.05]), np.full((1, 3), 2.0), 0.2),
        }
    )
    assert d.shape == (1, 3, 2)
    np.testing.assert_array_equal(o["g"], [[2.0, 2.0, 2.0]])


def test_release_through_forces_out_what_waits_on_a_silent_stream():
    m = LatestMerger("f", {"g": 0.0})
    m.push({"f": Chunk(np.array([0.1, 0.2, 0.3]), np.array([1.0, 2.0, 3.0]))})
    np.testing.assert_array_equal(m.held_times(), [0.1, 0.2, 0.3])
    t, d, o = m.release_through(0.2)
    np.testing.assert_array_equal(d, [1.0, 2.0])
    np.testing.assert_array_equal(t, [0.1, 0.2])
    np.testing.assert_array_equal(o["g"], [0.0, 0.0])
    np.testing.assert_array_equal(m.held_times(), [0.3])
