"""A checkpoint is data: its metadata is range-checked before a network is built, torch's refusal
is one line naming the file with the text from the file escaped, and only regular files are read."""

import json
import os

import pytest

torch = pytest.importorskip("torch")

from flowtact.blocks.teleop.cnn import (  # noqa: E402
    CHECKPOINT_FORMAT,
    load_checkpoint,
    read_meta,
    shipped_checkpoint,
)


def _meta(**arch):
    return {
        "format": CHECKPOINT_FORMAT,
        "format_version": 1,
        "arch": {"n_conv": 4, "width": 16, "fc": 128, "kernel": 3, "batch_norm": True, **arch},
        "preprocess": {"input_hw": [90, 240], "crop": None, "downsample": 4},
        "label_mean_n": 0.0,
        "label_std_n": 1.0,
    }


def _checkpoint(path, meta):
    torch.save(
        {"format": CHECKPOINT_FORMAT, "format_version": 1, "meta": json.dumps(meta), "state_dict": {}}, path
    )
    return path


def test_the_shipped_checkpoint_is_within_bounds():
    _, meta = load_checkpoint(shipped_checkpoint())
    assert meta["arch"]["width"] == 16 and read_meta(shipped_checkpoint())["arch"]["width"] == 16


@pytest.mark.parametrize(
    "arch,text",
    [
        ({"width": 5000}, "arch.width must be an integer in 1..1024; got 5000"),
        ({"n_conv": 99}, "arch.n_conv must be an integer in 1..8; got 99"),
        ({"fc": True}, "arch.fc must be an integer in 1..4096; got True"),
        ({"kernel": "3"}, "arch.kernel must be an integer in 1..15; got '3'"),
    ],
)
def test_embedded_metadata_is_range_checked_before_the_network_is_built(tmp_path, arch, text):
    path = _checkpoint(tmp_path / "m.pt", _meta(**arch))
    with pytest.raises(ValueError, match="m.pt: " + text.replace("(", r"\(").replace(")", r"\)")):
        load_checkpoint(path)


def test_a_network_too_large_for_the_budget_is_refused_from_its_metadata(tmp_path):
    meta = _meta(width=1024)
    meta["preprocess"] = {"input_hw": [4096, 4096], "crop": None, "downsample": 1}
    path = _checkpoint(tmp_path / "big.pt", meta)
    with pytest.raises(
        ValueError, match=r"big.pt: the network it describes would need about .* \(at most 1.0 GiB\)"
    ):
        load_checkpoint(path)


def test_torch_refusal_is_one_line_with_the_pickled_name_escaped(tmp_path):
    import sys
    import types

    module = "evil\x1b[2J\x1b]0;pwned\x07"
    sys.modules[module] = types.SimpleNamespace(Boom=type("Boom", (), {"__module__": module}))
    try:
        torch.save({"x": sys.modules[module].Boom()}, tmp_path / "evil.pt")
    finally:
        del sys.modules[module]
    for read in (load_checkpoint, read_meta):
        with pytest.raises(ValueError) as e:
            read(tmp_path / "evil.pt")
        text = str(e.value)
        assert "\n" not in text and "\x1b" not in text and "weights_only" not in text
        assert "evil.pt: not a flowtact CNN checkpoint (torch refused it: Unsupported global: " in text
        assert "GLOBAL evil\\x1b[2J\\x1b]0;pwned\\x07.Boom" in text


def test_only_regular_files_are_read(tmp_path):
    os.mkfifo(tmp_path / "m.pt")  # nobody writes: torch opening it would block
    for read in (load_checkpoint, read_meta):
        with pytest.raises(ValueError, match=r"m.pt: not a regular file \(a FIFO\)"):
            read(tmp_path / "m.pt")
    (tmp_path / "j.pt").write_bytes(b"junk")
    (tmp_path / "j.json").write_text("[" * 100_000)
    with pytest.raises(ValueError, match=r"j\.json: metadata is not JSON"):
        read_meta(tmp_path / "j.pt")
