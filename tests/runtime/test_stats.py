"""Latency histograms (flowtact.runtime.stats)."""

import math

import msgpack
import numpy as np
import pytest

from flowtact.runtime.stats import BUCKETS, LatencyHistogram


@pytest.fixture(scope="module")
def lognormal_ns() -> np.ndarray:
    """1e5 latencies around 150 µs with a long tail, in integer ns."""
    return np.random.default_rng(3).lognormal(mean=math.log(150e3), sigma=1.0, size=100_000).astype(np.int64)


def test_buckets_are_at_most_one_percent_wide():
    assert (100e9 / 1e3) ** (1 / BUCKETS) <= 1.01


@pytest.mark.parametrize("q", [1, 10, 50, 90, 99, 99.9])
def test_percentiles_within_one_percent_of_numpy(lognormal_ns, q):
    h = LatencyHistogram()
    for v in lognormal_ns.tolist():
        h.add(v)
    exact = np.percentile(lognormal_ns, q) / 1e3
    assert h.percentile(q) == pytest.approx(exact, rel=0.01)


def test_add_many_counts_like_add(lognormal_ns):
    one, many = LatencyHistogram(), LatencyHistogram()
    for v in lognormal_ns.tolist():
        one.add(v)
    many.add_many(lognormal_ns)
    np.testing.assert_array_equal(one.counts, many.counts)
    assert (one.n, one.sum, one.min, one.max) == (many.n, many.sum, many.min, many.max)


def test_summary_is_exact_for_count_max_and_mean(lognormal_ns):
    h = LatencyHistogram()
    h.add_many(lognormal_ns)
    s = h.summary()
    assert s["n"] == lognormal_ns.size
    assert s["max"] == lognormal_ns.max() / 1e3
    assert s["mean"] == pytest.approx(lognormal_ns.mean() / 1e3, rel=1e-12)
    assert s["p50"] == pytest.approx(np.median(lognormal_ns) / 1e3, rel=0.01)


def test_merge_equals_adding_everything_to_one(lognormal_ns):
    parts = np.array_split(lognormal_ns, 3)
    whole, merged = LatencyHistogram(), LatencyHistogram()
    whole.add_many(lognormal_ns)
    for part in parts:
        h = LatencyHistogram()
        h.add_many(part)
        merged.merge(h)
    merged.merge(LatencyHistogram())  # an empty one changes nothing
    np.testing.assert_array_equal(merged.counts, whole.counts)
    assert merged.summary() == whole.summary()
    assert (merged.min, merged.max, merged.sum) == (whole.min, whole.max, whole.sum)


def test_wire_round_trip_through_msgpack(lognormal_ns):
    h = LatencyHistogram()
    h.add_many(lognormal_ns[:1000])
    wire = h.to_wire()
    back = LatencyHistogram.from_wire(msgpack.unpackb(msgpack.packb(wire)))
    np.testing.assert_array_equal(back.counts, h.counts)
    assert back.summary() == h.summary()
    assert (back.min, back.max, back.sum) == (h.min, h.max, h.sum)
    # only non-zero buckets travel
    assert len(wire[4]) == 2 * np.count_nonzero(h.counts) < 2 * BUCKETS


def test_wire_round_trip_of_an_empty_histogram():
    back = LatencyHistogram.from_wire(msgpack.unpackb(msgpack.packb(LatencyHistogram().to_wire())))
    assert back.summary() == {"p50": None, "p99": None, "max": None, "mean": None, "n": 0}


@pytest.mark.parametrize(
    "bad", [None, [1, 2], [1, 10, 10, 10, [BUCKETS, 1]], [2, 10, 5, 5, [3, 1]], [1, 5, None, None, [3, 1]]]
)
def test_malformed_wire_is_refused(bad):
    with pytest.raises(ValueError):
        LatencyHistogram.from_wire(bad)


def test_extremes_go_to_the_end_buckets_and_percentiles_are_clamped():
    h = LatencyHistogram()
    for ns in (0, -5_000, 300, 500):  # below 1 µs, including clock skew
        h.add(ns)
    assert h.counts[0] == 4
    assert h.min == -5_000
    assert h.percentile(50) == pytest.approx(0.5)  # bucket centre ~1 µs, clamped to max 0.5 µs
    h.reset()
    for ns in (200 * 10**9, 500 * 10**9):  # above 100 s
        h.add(ns)
    assert h.counts[-1] == 2 and h.n == 2
    assert h.percentile(1) == 200e6  # bucket centre ~100 s, clamped up to min 200 s
    assert h.percentile(100) == 500e6


def test_percentile_of_one_value_is_that_value():
    h = LatencyHistogram()
    h.add(123_456)
    assert h.percentile(0) == h.percentile(50) == h.percentile(100) == 123.456


def test_reset_empties():
    h = LatencyHistogram()
    h.add_many(np.array([1_000, 2_000, 3_000]))
    h.reset()
    assert h.n == 0 and h.counts.sum() == 0 and h.min is None and h.percentile(50) is None
    h.add(7_000)
    assert h.summary()["p50"] == 7.0 and h.summary()["max"] == 7.0
