"""TouchSim's development set: one copy (tests/data/touchsim_dev.npz), one loader
(flowtact.bench.touchsim_dev_set) that the bench, the scripts and the tests share."""

from __future__ import annotations

import numpy as np
from runs import ROOT

from flowtact.bench.touchsim_dev_set import CHECKOUT_COPY, load_dev_set


def test_the_loader_gives_every_array_of_the_file():
    """All five arrays of all 68 traces, bit for bit, and nothing in the file left unread."""
    dev = load_dev_set(CHECKOUT_COPY)
    with np.load(CHECKOUT_COPY) as z:
        assert len(dev.names) == 68 and len(z.files) == 5 * 68
        for name in dev.names:
            got = dev.trace(name)
            for field in ("s", "d", "I", "p", "spk"):
                np.testing.assert_array_equal(got[field], z[f"{name}|{field}"], err_msg=f"{name}|{field}")
    assert dev.params.shape == (68, 13) and dev.current.shape == (4000, 68)


def test_no_second_copy_of_the_traces_in_the_checkout():
    """No other array file under tests/, graphs/ or bench/ holds a trace's current (an old copy)."""
    dev = load_dev_set(CHECKOUT_COPY)
    currents = {dev.current[:, k].tobytes() for k in range(len(dev.names))}
    copies = []
    for path in [p for d in ("tests", "graphs", "bench") for p in (ROOT / d).rglob("*.npz")]:
        if path == CHECKOUT_COPY:
            continue
        with np.load(path) as z:
            for key in z.files:
                if z[key].dtype.kind != "f":
                    continue
                a = z[key]
                rows = a.reshape(-1, a.shape[-1]) if a.ndim > 1 else a[None]
                cols = a.reshape(a.shape[0], -1).T if a.ndim > 1 else a[None]
                if any(r.tobytes() in currents for r in (*rows, *cols) if len(r) == 4000):
                    copies.append(f"{path.relative_to(ROOT)}:{key}")
    assert not copies, copies
