"""The pulses block: one pulse per spike, and a safety envelope that holds whatever the input."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec
from flowtact.blocks.spiking.pulses import (
    BAD_UNIT,
    DELIVERED,
    DROPPED_RATE,
    NONFINITE,
    Pulses,
    pulse_kernel,
    pulse_kernel_py,
)
from flowtact.testing import assert_same, run_offline

UA = {"amplitude": "uA"}


def spikes(*pairs):
    t, u = zip(*pairs, strict=True) if pairs else ((), ())
    return np.array(t, np.float64), np.array(u, np.int64)


def specs_for(n_units, amp=None):
    """Specs as a graph gives them (run_offline would infer n_units from the largest index seen)."""
    out = {"spikes": StreamSpec(dtype="int64", events=True, n_units=n_units)}
    if amp is not None:
        out["amplitude"] = StreamSpec(shape=np.shape(amp)[1:], units="uA", rate_hz=1000.0)
    return out


def run(block, chunk=None, n_units=None, **inputs):
    amp = inputs.get("amplitude")
    if n_units is None:
        n_units = (
            np.shape(amp)[1] if amp is not None and np.ndim(amp) > 1 else int(inputs["spikes"][1].max()) + 1
        )
    return run_offline(block, chunk=chunk, specs=specs_for(n_units, amp), **inputs)["y"]


def test_one_pulse_per_spike_with_the_nominal_pulse():
    out = run(Pulses(amplitude_ua=40.0, width_us=150.0), spikes=spikes((0.01, 0), (0.02, 2), (0.05, 0)))
    np.testing.assert_array_equal(out.t, [0.01, 0.02, 0.05])
    np.testing.assert_array_equal(out.data, [[0, 40.0, 150.0], [2, 40.0, 150.0], [0, 40.0, 150.0]])
    specs = Pulses().bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=3)})
    assert specs["y"].labels == ("unit", "amplitude_ua", "width_us") and specs["y"].events


def test_rate_limit_counts_from_the_last_delivered_pulse_of_each_unit():
    # max 300/s → at least 3.33 ms between delivered pulses of a unit
    s = spikes((0.000, 0), (0.002, 0), (0.002, 1), (0.004, 0), (0.006, 0), (0.007, 0), (0.008, 0), (0.003, 1))
    order = np.argsort(s[0], kind="stable")
    block = Pulses(max_rate_hz=300.0)
    out = run(block, spikes=(s[0][order], s[1][order]))
    got = sorted(zip(out.t.tolist(), out.data[:, 0].astype(int).tolist(), strict=True))
    assert got == [(0.0, 0), (0.002, 1), (0.004, 0), (0.008, 0)]
    assert block.counters == {"dropped_rate": 4}


def test_a_1_mhz_burst_gives_one_pulse():
    t = 0.1 + 1e-6 * np.arange(1000)
    block = Pulses(max_rate_hz=200.0)
    out = run(block, spikes=(t, np.zeros(1000, np.int64)))
    assert len(out) == 1 and out.t[0] == 0.1
    assert block.counters["dropped_rate"] == 999


def test_amplitude_is_sample_and_hold_and_clipped_to_the_envelope():
    n = 100
    amp = np.full((n, 2), 50.0)
    amp[20:, 0] = 1000.0  # above max (250) and above the charge ceiling 40 nC / 200 µs = 200 µA
    amp[40:, 0] = 2.0  # below min → no pulse
    amp[60:, 1] = 230.0  # below max but above the charge ceiling
    block = Pulses(
        amplitude_ua=50.0,
        width_us=200.0,
        max_amplitude_ua=250.0,
        min_amplitude_ua=5.0,
        max_charge_nc=40.0,
        max_ramp_ua_per_s=1e9,
    )
    s = spikes((0.0100, 0), (0.0200, 0), (0.0255, 0), (0.0450, 0), (0.0595, 1), (0.0600, 1), (0.0700, 1))
    out = run(block, amplitude=amp, spikes=s)
    np.testing.assert_array_equal(out.t, [0.0100, 0.0200, 0.0255, 0.0595, 0.0700])
    np.testing.assert_array_equal(out.data[:, 1], [50.0, 200.0, 200.0, 50.0, 200.0])
    assert block.counters == {
        "clipped_amplitude": 2,
        "dropped_amplitude": 1,
        "clipped_charge": 3,
        "dropped_rate": 1,
    }


def test_amplitude_change_between_pulses_is_ramp_limited():
    amp = np.concatenate([np.full(50, 20.0), np.full(50, 200.0), np.full(100, 10.0)])
    s = spikes(*[(k * 0.010, 0) for k in range(20)])
    block = Pulses(amplitude_ua=20.0, max_amplitude_ua=250.0, max_charge_nc=50.0, max_ramp_ua_per_s=2000.0)
    out = run(block, amplitude=amp, spikes=s)
    a = out.data[:, 1]
    assert np.all(np.abs(np.diff(a)) <= 2000.0 * 0.010 + 1e-9)
    np.testing.assert_allclose(a[:6], [20, 20, 20, 20, 20, 40])  # 20 µA per 10 ms upwards
    assert a.max() < 200.0 and a[-1] == 10.0  # never reached 200, then walked back down to 10
    assert block.counters["ramp_limited"] > 0


def test_scalar_amplitude_applies_to_every_unit_and_nominal_before_the_first_sample():
    amp = np.full(50, 90.0)
    t = np.arange(50) / 1000.0 + 0.010  # the amplitude stream starts at 10 ms
    block = Pulses(amplitude_ua=30.0, max_ramp_ua_per_s=1e9)
    out = run_offline(block, units=UA, t=t, amplitude=amp, spikes=spikes((0.012, 0), (0.013, 3)))["y"]
    np.testing.assert_array_equal(out.data[:, 1], [90.0, 90.0])
    block = Pulses(amplitude_ua=30.0)
    stepped = block.bind(
        {
            "spikes": StreamSpec(dtype="int64", events=True, n_units=2),
            "amplitude": StreamSpec(units="uA", rate_hz=1000.0),
        }
    )
    assert stepped["y"].n_units == 2
    y = block(
        spikes=Chunk(np.array([0.001]), np.array([1])), amplitude=Chunk(np.array([0.002]), np.array([80.0]))
    )
    assert y["y"].data.tolist() == [[1.0, 30.0, 200.0]]  # before the first sample: amplitude_ua


def test_spikes_wait_for_the_amplitude_stream():
    block = Pulses(max_ramp_ua_per_s=1e9)
    block.bind(
        {
            "spikes": StreamSpec(dtype="int64", events=True, n_units=1),
            "amplitude": StreamSpec(units="uA", rate_hz=1000.0),
        }
    )
    empty = Chunk(np.empty(0), np.empty(0))
    first = block(spikes=Chunk(np.array([0.0005, 0.0042]), np.array([0, 0]), 0.005), amplitude=empty)
    assert len(first["y"]) == 0
    second = block(
        spikes=Chunk(np.empty(0), np.empty(0, np.int64), 0.006),
        amplitude=Chunk(np.arange(5) / 1000.0, np.array([10.0, 20.0, 30.0, 40.0, 50.0])),
    )
    np.testing.assert_array_equal(second["y"].t, [0.0005])
    assert second["y"].data[0, 1] == 10.0 and second["y"].end == 0.004
    third = block(amplitude=Chunk(np.array([0.005]), np.array([60.0])))
    np.testing.assert_array_equal(third["y"].data[:, 1], [50.0])  # 4.2 ms: the 4 ms sample
    assert block.flush() == {}


@pytest.mark.parametrize("policy", ["drop", "hold"])
def test_nonfinite_amplitude_samples_follow_the_policy(policy):
    amp = np.full((30, 2), 70.0)
    amp[10:20, 0] = [np.nan, np.inf, -np.inf, np.nan, 70, 70, np.nan, 70, 70, 70]
    s = spikes(*[(k * 0.004, 0) for k in range(7)])
    block = Pulses(on_bad_data=policy, amplitude_ua=60.0, max_ramp_ua_per_s=1e9)
    out = run(block, amplitude=amp, spikes=s)
    assert len(out) == 7 and np.all(out.data[:, 1] == 70.0)
    assert block.counters == {f"nonfinite_{policy}": 5}
    with pytest.raises(BadDataError, match="amplitude"):
        run(Pulses(), amplitude=amp, spikes=s)


def test_bad_event_times_and_units_are_dropped():
    block = Pulses()
    block.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=2)})
    y = block(spikes=Chunk(np.array([0.001, np.nan, 0.002, 0.003]), np.array([0, 0, 5, -1])))
    assert y["y"].t.tolist() == [0.001]
    assert block.counters == {"bad_time": 1, "bad_unit": 2}


def test_spec_errors():
    ev = StreamSpec(dtype="int64", events=True, n_units=4)
    with pytest.raises(SpecError, match="uA"):
        Pulses().bind({"spikes": ev, "amplitude": StreamSpec(units="mA", rate_hz=1000.0)})
    with pytest.raises(SpecError, match=r"\(4,\)"):
        Pulses().bind({"spikes": ev, "amplitude": StreamSpec(shape=(3,), units="uA", rate_hz=1000.0)})
    with pytest.raises(SpecError, match="max_units"):
        Pulses(max_units=2).bind({"spikes": ev})
    with pytest.raises(SpecError, match="event"):
        Pulses().bind({"spikes": StreamSpec(dtype="int64", rate_hz=1000.0)})
    with pytest.raises(SpecError, match="integer"):
        Pulses().bind({"spikes": StreamSpec(dtype="float64", events=True, n_units=4)})


def test_config_must_put_the_nominal_pulse_inside_the_envelope():
    with pytest.raises(ConfigError, match="amplitude_ua"):
        Pulses(amplitude_ua=300.0, max_amplitude_ua=250.0)
    with pytest.raises(ConfigError, match="max_charge_nc"):
        Pulses(amplitude_ua=100.0, width_us=400.0, max_charge_nc=30.0)
    with pytest.raises(ConfigError, match="min_amplitude_ua"):
        Pulses(min_amplitude_ua=300.0, max_amplitude_ua=250.0)
    with pytest.raises(ConfigError, match="width_us"):
        Pulses(width_us=4000.0, max_rate_hz=300.0, max_charge_nc=1000.0)


def test_numba_kernel_equals_its_python_twin():
    rng = np.random.default_rng(0)
    n, units = 3000, 5
    t = np.sort(rng.uniform(0, 1.0, n))
    t[100:110] = np.nan
    u = rng.integers(-1, units + 1, n)
    req = rng.choice([np.nan, np.inf, -5.0, 0.0, 3.0, 60.0, 400.0, 1e300], n) * rng.uniform(0.5, 1.5, n)
    results = []
    for kernel in (pulse_kernel, pulse_kernel_py):
        last_t, last_a = np.full(units, -np.inf), np.zeros(units)
        out_a, flags = np.full(n, -1.0), np.zeros(n, np.int64)
        kernel(t, u, req, units, 1 / 300.0, 5.0, 250.0, 150.0, 3000.0, last_t, last_a, out_a, flags)
        results.append((out_a, flags, last_t, last_a))
    for a, b in zip(*results, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
    flags = results[0][1]
    assert {DELIVERED, DROPPED_RATE, BAD_UNIT, NONFINITE} <= set(flags.tolist())


# -- property: the envelope holds whatever the input ------------------------------------------------

finite_or_garbage = st.one_of(
    st.floats(-1e3, 1e3),
    st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0, 4.999, 5.0]),
)


@st.composite
def scenario(draw):
    n_units = draw(st.integers(1, 4))
    n = 200  # amplitude samples at 1 kHz
    n_spikes = draw(st.integers(0, 120))
    ticks = draw(st.lists(st.integers(0, n * 1000 - 1), min_size=n_spikes, max_size=n_spikes))
    burst = draw(st.integers(0, 40))  # a 1 MHz burst
    start = draw(st.integers(0, n * 1000 - 100))
    ticks += [start + k for k in range(burst)]
    units = draw(st.lists(st.integers(0, n_units - 1), min_size=len(ticks), max_size=len(ticks)))
    order = np.lexsort((units, ticks))
    t = np.asarray(ticks, np.float64)[order] * 1e-6
    u = np.asarray(units, np.int64)[order]
    levels = draw(st.lists(finite_or_garbage, min_size=1, max_size=12))
    idx = draw(st.lists(st.integers(0, len(levels) - 1), min_size=n * n_units, max_size=n * n_units))
    amp = np.asarray(levels, np.float64)[idx].reshape(n, n_units)
    params = dict(
        amplitude_ua=draw(st.floats(5.0, 100.0)),
        width_us=draw(st.floats(50.0, 400.0)),
        max_rate_hz=draw(st.floats(50.0, 1000.0)),
        min_amplitude_ua=5.0,
        max_amplitude_ua=draw(st.floats(100.0, 300.0)),
        max_charge_nc=draw(st.floats(40.0, 60.0)),
        max_ramp_ua_per_s=draw(st.floats(100.0, 1e5)),
        on_bad_data=draw(st.sampled_from(["drop", "hold"])),
    )
    chunk = draw(st.lists(st.integers(1, 80), min_size=1, max_size=5))
    return params, t, u, amp, chunk


def requested(params, amp, t_spk, u_spk):
    """Requested amplitude per spike: non-finite samples replaced per policy, sample-and-hold."""
    clean = np.array(amp)
    if params["on_bad_data"] == "hold":
        prev = np.full(amp.shape[1], params["amplitude_ua"])
        for i in range(len(clean)):
            bad = ~np.isfinite(clean[i])
            clean[i, bad] = prev[bad]
            prev = clean[i]
        times = np.arange(len(amp)) / 1000.0
    else:
        keep = np.isfinite(amp).all(axis=1)
        clean, times = clean[keep], (np.arange(len(amp)) / 1000.0)[keep]
    k = np.searchsorted(times, t_spk, side="right") - 1
    rows = np.full((len(t_spk), amp.shape[1]), params["amplitude_ua"])
    rows[k >= 0] = clean[k[k >= 0]]
    return rows[np.arange(len(t_spk)), u_spk]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenario())
def test_envelope_holds_and_counters_account_for_every_change(case):
    params, t, u, amp, chunk = case
    if params["amplitude_ua"] * params["width_us"] / 1000 > params["max_charge_nc"]:
        params["amplitude_ua"] = 5.0
    block = Pulses(**params)
    inputs = dict(spikes=(t, u), amplitude=amp)
    out = run_offline(block, specs=specs_for(amp.shape[1], amp), **inputs)["y"]
    c = block.config
    a, units = out.data[:, 1], out.data[:, 0].astype(np.int64)
    ceiling = min(c.max_amplitude_ua, 1000 * c.max_charge_nc / c.width_us)
    assert np.all(np.isfinite(out.data)) and np.all(np.isfinite(out.t))
    assert np.all((a >= c.min_amplitude_ua) & (a <= ceiling))
    assert np.all(a * out.data[:, 2] / 1000 <= c.max_charge_nc * (1 + 1e-12))
    assert np.all(out.data[:, 2] == c.width_us)
    for unit in np.unique(units):
        tu, au = out.t[units == unit], a[units == unit]
        gaps = np.diff(tu)
        assert np.all(gaps >= 1.0 / c.max_rate_hz)
        assert np.all(np.abs(np.diff(au)) <= c.max_ramp_ua_per_s * gaps * (1 + 1e-9) + 1e-9)
    # every dropped spike is counted exactly once; every changed amplitude is counted
    k = block.counters
    drops = sum(k.get(name, 0) for name in ("dropped_rate", "dropped_amplitude", "bad_unit", "bad_time"))
    assert len(t) == len(out) + drops
    req = requested(params, amp, t, u)
    delivered = np.isin(np.arange(len(t)), _match(t, u, out.t, units))
    changed = int(np.count_nonzero(req[delivered] != a))
    assert changed <= k.get("clipped_amplitude", 0) + k.get("clipped_charge", 0) + k.get("ramp_limited", 0)
    assert k.get("dropped_amplitude", 0) == int(np.count_nonzero(~(req >= c.min_amplitude_ua)))
    # chunking does not change a bit
    again = run_offline(
        Pulses(**params), specs=specs_for(amp.shape[1], amp), chunk=chunk, empty_between=True, **inputs
    )["y"]
    assert_same({"y": again}, {"y": out})


def _match(t, u, out_t, out_u):
    """Indices of the input spikes that were delivered (outputs keep the input order)."""
    idx, j = [], 0
    for i in range(len(t)):
        if j < len(out_t) and t[i] == out_t[j] and u[i] == out_u[j]:
            idx.append(i)
            j += 1
    assert j == len(out_t)
    return np.array(idx, np.int64)
