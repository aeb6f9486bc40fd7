"""`flowtact bench touchsim`'s own logic: what counts as agreeing with TouchSim, and its stimulus."""

import numpy as np

from flowtact.bench.touchsim import agreement, stimulus
from flowtact.bench.touchsim_dev_set import dev_set_path, load_dev_set


def test_agreement_counts_a_spike_one_sample_off_as_within_one_and_two_off_as_not():
    want = [np.array([10, 20]), np.array([5]), np.array([], np.int64), np.array([7, 9])]
    got = [np.array([10, 20]), np.array([6]), np.array([], np.int64), np.array([7, 11])]
    r = agreement(got, want)
    assert (r["same_count"], r["within_1"], r["identical"]) == (4, 3, 2)
    r = agreement([np.array([10]), *got[1:]], want)  # a spike missing: not the same count
    assert (r["same_count"], r["within_1"]) == (3, 2)


def test_the_speed_stimulus_is_one_second_of_the_dev_set_wrapped_in_time_and_across_afferents():
    dev = load_dev_set(dev_set_path())
    s, d, models, cls, idx = stimulus(dev, 150)
    assert s.shape == d.shape == (5000, 150) and s.flags.c_contiguous
    np.testing.assert_array_equal(s[:4000, 69], dev.s[:, 1])  # column 69 is trace 1
    np.testing.assert_array_equal(d[4000:, 3], dev.d[:1000, 3])  # samples 4000… wrap to the start
    assert models[68] == dev.models[0] and cls[70] == dev.cls[2] and idx[70] == dev.idx[2]
