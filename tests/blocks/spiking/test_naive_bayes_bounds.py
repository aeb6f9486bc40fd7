"""A naive Bayes model file is data: read within bounds (no pickles, sizes from the headers) and
every field range-checked, with messages that show the file's text escaped."""

import hashlib
import json
import os

import numpy as np
import pytest

from flowtact.blocks.spiking.naive_bayes import example_model_path
from flowtact.blocks.spiking.nb_model import ModelError, load_model


def _write(path, meta, arrays):
    """A model file with ``meta`` (its checksum recomputed, as a trainer would) and ``arrays``."""
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k], np.float64)
        h.update(k.encode() + str(a.shape).encode() + a.tobytes())
    keys = ("likelihood", "features", "classes", "n_units", "n_bins", "running_temperature")
    h.update(json.dumps({k: meta.get(k) for k in keys}, sort_keys=True).encode())
    np.savez(path, meta=np.array(json.dumps({**meta, "sha256": h.hexdigest()})), **arrays)
    return path


def _example():
    with np.load(example_model_path()) as z:
        return json.loads(str(z["meta"])), {k: z[k] for k in z.files if k != "meta"}


def test_the_example_model_loads():
    assert load_model(example_model_path()).n_units > 0


@pytest.mark.parametrize(
    "change,text",
    [
        ({"n_bins": 10**9}, "n_bins must be an integer in 1..10,000; got 1000000000"),
        ({"n_units": True}, "n_units must be an integer in 1..1,000,000; got True"),
        ({"n_units": 2.5}, "n_units must be an integer in 1..1,000,000; got 2.5"),
        ({"classes": "abc"}, "classes must be a list of 1..10,000 names"),
        ({"running_temperature": float("nan")}, "running_temperature must be in (0, 1]; got nan"),
    ],
)
def test_fields_are_range_checked_even_with_a_valid_checksum(tmp_path, change, text):
    meta, arrays = _example()
    with pytest.raises(ModelError) as e:
        load_model(_write(tmp_path / "m.npz", {**meta, **change}, arrays))
    assert text in str(e.value)


def test_a_pickled_member_and_escapes_in_the_file_are_refused_as_data(tmp_path):
    meta, arrays = _example()
    np.savez(tmp_path / "p.npz", meta=np.array(json.dumps(meta)), x=np.array([{}], dtype=object))
    with pytest.raises(ModelError, match=r"member x\.npy holds Python objects \(a pickle\): refused"):
        load_model(tmp_path / "p.npz")
    with pytest.raises(ModelError) as e:
        load_model(_write(tmp_path / "f.npz", {**meta, "format": "x\x1b[2J"}, arrays))
    assert "\x1b" not in str(e.value) and "x\\x1b[2J" in str(e.value)


def test_a_fifo_is_refused_without_blocking(tmp_path):
    os.mkfifo(tmp_path / "m.npz")
    with pytest.raises(
        ModelError, match=r"not a readable naive Bayes model file \(not a regular file \(a FIFO\)\)"
    ):
        load_model(tmp_path / "m.npz")
