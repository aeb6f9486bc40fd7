"""ClockSync on synthetic devices: offset, drift, one-sided jitter, host polling, wraps, resets."""

import numpy as np
import pytest

from flowtact.blocks.devices.clocksync import ClockSync, lower_hull_slope

RATE = 100.0  # device packets per second
WRAP = 1 << 32


def synthetic(
    duration_s: float,
    *,
    drift_ppm: float | list[tuple[float, float]] = 0.0,
    offset_s: float = 3.2,
    jitter: str = "exp",
    poll: str = "dither",
    tick_s: float = 0.005,
    tick0: int = WRAP - 3_000_000,
    seed: int = 0,
):
    """A device sampling every 10 ms of its own clock, read by a host polling every ~``tick_s``.

    Returns device ticks (uint32, wrapping), true host times of the samples, host read times and
    the previous read times (the ``after`` bounds). ``drift_ppm`` is host seconds per device second
    minus one, in ppm, or a list of (from time s, ppm) steps. Jitter is one-sided: ``exp`` (mean
    2 ms), ``uni`` (0–8 ms) or ``none``; the line is FIFO. ``poll``: ``dither`` (intervals uniform
    in 0.8–1.3 × tick, as a busy host) or ``grid`` (exact multiples of the tick: phase-locked).
    """
    rng = np.random.default_rng(seed)
    n = int(duration_s * RATE)
    steps = [(0.0, drift_ppm)] if np.isscalar(drift_ppm) else list(drift_ppm)
    period = np.empty(n)
    for i in range(n):
        ppm = [p for start, p in steps if i / RATE >= start][-1]
        period[i] = (1.0 + ppm * 1e-6) / RATE
    true = offset_s + np.concatenate([[0.0], np.cumsum(period[:-1])])
    ticks = (tick0 + np.arange(n) * 10_000) % WRAP
    if jitter == "exp":
        delay = rng.exponential(0.002, n)
    elif jitter == "uni":
        delay = rng.uniform(0.0, 0.008, n)
    else:
        delay = np.zeros(n)
    arrive = np.maximum.accumulate(true + delay)
    if poll == "grid":
        polls = np.arange(0.0, true[-1] + 1.0, tick_s)
    else:
        polls = np.cumsum(rng.uniform(0.8 * tick_s, 1.3 * tick_s, int((true[-1] + 1.0) / tick_s) + 10))
    k = np.searchsorted(polls, arrive)
    return ticks, true, polls[k], polls[k - 1]


def stamp_all(sync, ticks, reads, afters, use_after=True):
    out = np.empty(len(ticks))
    for i in range(len(ticks)):
        s = sync.add(int(ticks[i]), float(reads[i]), float(afters[i]) if use_after else None)
        out[i] = np.nan if s is None else s
    return out


@pytest.mark.parametrize("drift", [200.0, -200.0])
@pytest.mark.parametrize("jitter", ["exp", "uni"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_offset_drift_jitter_and_polling(drift, jitter, seed):
    # offset 3.2 s, ±200 ppm, one-sided jitter, a host polling every ~5 ms, a wrap at 30 s
    ticks, true, reads, afters = synthetic(20.0, drift_ppm=drift, jitter=jitter, seed=seed)
    sync = ClockSync()
    err = stamp_all(sync, ticks, reads, afters) - true
    assert np.isfinite(err).all()
    # exp: most packets come fast; uni 0–8 ms: few do, and polling adds up to a tick on top
    bound_5s, bound_10s, bound_median, bound_drift = (
        (1e-3, 1e-3, 0.5e-3, 40) if jitter == "exp" else (2e-3, 1.5e-3, 1e-3, 60)
    )
    late = np.abs(err[int(5 * RATE) :])  # after a few seconds
    assert late.max() < bound_5s
    assert np.median(late) < bound_median
    assert np.abs(err[int(10 * RATE) :]).max() < bound_10s  # once the drift is settled
    assert sync.drift_ppm == pytest.approx(drift, abs=bound_drift)
    assert (np.asarray(reads) - (err + true) >= -1e-12).all()  # a stamp is never after its read


def test_raw_arrival_stamps_are_much_worse():
    # what the estimator buys: the read times themselves are late by jitter + polling
    ticks, true, reads, afters = synthetic(20.0, drift_ppm=150.0, jitter="uni", seed=4)
    err = stamp_all(ClockSync(), ticks, reads, afters) - true
    raw = reads - true
    assert np.median(raw[500:]) > 5 * np.median(np.abs(err[500:]))


def test_tick_wraps_are_continuous():
    ticks, true, reads, afters = synthetic(10.0, tick0=WRAP - 2_000_000, jitter="none", poll="dither")
    assert ticks[300] < ticks[100]  # it wrapped at 2 s
    sync = ClockSync()
    stamps = stamp_all(sync, ticks, reads, afters)
    assert np.isfinite(stamps).all()
    assert (np.diff(stamps[10:]) > 0.009).all()  # after the first packets (stamped at their reads)
    assert sync.resyncs == 0 and sync.dropped == 0
    assert sync.ticks == 999 * 10_000
    assert np.abs(stamps[200:] - true[200:]).max() < 1e-3  # straight through the wrap


def test_phase_locked_polling_is_bounded_by_the_tick():
    # device period = 2 host ticks, no jitter, no drift: the read phase is locked and invisible.
    # Plain lower envelope: late by (tick − phase), up to one tick. With the previous read as a lower
    # bound the stamps move to the middle of the bracket: at most half a tick either way.
    worst_after, worst_plain = [], []
    for phase in (0.0004, 0.0013, 0.0024, 0.0036, 0.0046):
        ticks, true, reads, afters = synthetic(15.0, jitter="none", poll="grid", offset_s=3.2 + phase)
        with_after = stamp_all(ClockSync(), ticks, reads, afters) - true
        plain = stamp_all(ClockSync(), ticks, reads, afters, use_after=False) - true
        worst_after.append(np.abs(with_after[500:]).max())
        worst_plain.append(np.abs(plain[500:]).max())
        assert sync_uncertainty(ticks, reads, afters) == pytest.approx(0.0025, abs=3e-4)
    assert max(worst_after) <= 0.0025 + 1e-4
    assert max(worst_plain) <= 0.005 + 1e-4
    assert max(worst_plain) > 0.004  # the locked phase is a real limit without the bracket


def sync_uncertainty(ticks, reads, afters):
    sync = ClockSync()
    stamp_all(sync, ticks, reads, afters)
    return sync.uncertainty_s


def test_tracks_a_drift_step():
    ticks, true, reads, afters = synthetic(50.0, drift_ppm=[(0.0, 100.0), (20.0, -100.0)], seed=3)
    sync = ClockSync()
    err = np.abs(stamp_all(sync, ticks, reads, afters) - true)
    step = int(20 * RATE)
    assert err[500:step].max() < 1e-3
    assert err[step:].max() < 1.5e-3  # while the slope catches up
    assert err[step + int(20 * RATE) :].max() < 1e-3  # a drift window later
    assert sync.drift_ppm == pytest.approx(-100.0, abs=30.0)


def test_resyncs_after_a_device_reset_and_drops_duplicates():
    ticks, true, reads, afters = synthetic(20.0, drift_ppm=-80.0, seed=5)
    reset_at = int(8 * RATE)
    ticks = ticks.copy()
    ticks[reset_at:] = (123_456 + np.arange(len(ticks) - reset_at) * 10_000) % WRAP  # rebooted
    sync = ClockSync()
    stamps = np.empty(len(ticks))
    for i in range(len(ticks)):
        stamps[i] = sync.add(int(ticks[i]), reads[i], afters[i])
        if i in (100, 1000):  # a duplicated packet and a reordered one are dropped
            assert sync.add(int(ticks[i]), reads[i], afters[i]) is None
            assert sync.add(int(ticks[i - 1]), reads[i], afters[i]) is None
    assert sync.resyncs == 1
    assert sync.dropped == 4
    assert sync.drift_ppm == pytest.approx(-80.0, abs=40.0)  # kept across the reset
    err = np.abs(stamps - true)
    assert err[reset_at + 300 :].max() < 1e-3


def test_forward_clock_jump_resyncs():
    ticks, true, reads, afters = synthetic(8.0, seed=6)
    ticks = ticks.copy()
    ticks[400:] = (ticks[400:] + 50_000_000) % WRAP  # the counter jumped 50 s ahead
    sync = ClockSync()
    err = np.abs(stamp_all(sync, ticks, reads, afters) - true)
    assert sync.resyncs == 1
    assert err[600:].max() < 1.5e-3


def test_lower_hull_slope():
    rng = np.random.default_rng(0)
    d = np.linspace(0.0, 20.0, 400)
    u = 5.0 + 1.0002 * d + rng.exponential(0.002, d.size)
    u[::50] = 5.0 + 1.0002 * d[::50]  # some packets with no delay at all
    assert lower_hull_slope(d, u, 0.99, 1.01) == pytest.approx(1.0002, abs=2e-6)
    assert lower_hull_slope(d, u, 0.99, 1.0001) == 1.0001  # clamped
    assert lower_hull_slope(d[:1], u[:1], 0.99, 1.01) == 1.0


def test_state_snapshot():
    sync = ClockSync()
    assert not sync.state().synced
    ticks, true, reads, afters = synthetic(3.0, seed=7)
    stamp_all(sync, ticks, reads, afters)
    st = sync.state()
    assert st.synced and st.n_points == 300 and st.resyncs == 0
    assert st.offset_s == pytest.approx(true[0], abs=2e-3)
    assert 0.0 <= st.uncertainty_s < 5e-3
