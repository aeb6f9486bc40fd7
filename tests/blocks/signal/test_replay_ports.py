"""The replay that stands in for a node on the replaced block's own ports (what --replay builds)."""

import numpy as np
import pytest

from flowtact.blocks.signal.replay_ports import stand_in_class
from flowtact.catalog.blocks import load_block
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
from flowtact.recording.hdf5 import Recorder
from flowtact.testing import CHECKS, run_source

SENSOR = stand_in_class("aunp_sensor")


def write_csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return str(path)


def rows(n=5, rate=100.0, width=5):
    return [[i / rate, *(i * 10 + k for k in range(width))] for i in range(n)]


def test_the_stand_in_has_the_replaced_ports_and_is_found_by_its_block_reference():
    assert list(SENSOR.outputs) == list(load_block("aunp_sensor").outputs)
    assert SENSOR.outputs["r"] == load_block("aunp_sensor").outputs["r"]
    ref = load_block("replay").stand_in("aunp_sensor")
    assert load_block(ref) is SENSOR
    assert stand_in_class(ref) is SENSOR  # replaying a replay: the same ports
    with pytest.raises(Exception, match="no stand-in replay for block 'nope'"):
        load_block(load_block("replay").stand_in("nope"))


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__)
def test_conformance(check):
    check(SENSOR)


@pytest.mark.parametrize("style", ["r[{i}]", "r.{i}", "r_{i}"])
def test_csv_columns_found_by_port_name(tmp_path, style):
    header = ["t", *(style.format(i=i) for i in range(4)), "ref"]
    b = SENSOR(path=write_csv(tmp_path / "log.csv", header, rows()), node="sensor")
    out = run_source(b, 0.05, tick_s=0.02)
    assert set(out) == {"r", "ref"}  # temp_c and force: not in the file, no stream
    assert b.output_specs["r"] == StreamSpec("float64", (4,), "1", 100.0, labels=tuple(header[1:5]))
    assert b.output_specs["ref"] == StreamSpec("float64", (), "1", 100.0)
    np.testing.assert_array_equal(out["r"].data[:, 3], [3, 13, 23, 33, 43])
    np.testing.assert_array_equal(out["ref"].data, [4, 14, 24, 34, 44])
    assert b.ends_at({}) == pytest.approx(0.05)


def test_explicit_map_and_units_from_the_replaced_port(tmp_path):
    path = write_csv(tmp_path / "log.csv", ["t", "g4", "g3", "g2", "g1", "truth"], rows(width=5))
    b = SENSOR(path=path, ports="r=g1,g2,g3,g4;force=truth,truth,truth", node="sensor")
    out = run_source(b, 0.05)
    np.testing.assert_array_equal(out["r"].data[0], [3, 2, 1, 0])
    assert b.output_specs["force"].units == "N" and out["force"].data.shape == (5, 3)
    assert "ref" not in out


def test_mapping_errors_say_what_would_be_right(tmp_path):
    path = write_csv(tmp_path / "log.csv", ["t", "g1", "g2", "g3", "g4", "gref"], rows())
    with pytest.raises(
        SpecError,
        match=r"no column for ports 'r', 'ref' of aunp_sensor .*"
        r"--replay 'sensor=.*log\.csv:r=C1,C2,C3,C4;ref=COLUMN'",
    ):
        SENSOR(path=path, need=["r", "ref"], node="sensor").bind({})
    with pytest.raises(
        SpecError, match=r"port 'ref': no column 'gre' in .*log\.csv \(did you mean 'gref'\?\)"
    ):
        SENSOR(path=path, ports="ref=gre").bind({})
    with pytest.raises(SpecError, match=r"'rr' is not an output of aunp_sensor \(did you mean 'r'\?\)"):
        SENSOR(path=path, ports="rr=g1").bind({})
    with pytest.raises(
        SpecError,
        match=r"port 'r' of aunp_sensor takes samples of shape \(4,\) \(4 columns\); "
        r"'g1, g2, g3' in .* gives \(3,\)",
    ):
        SENSOR(path=path, ports="r=g1,g2,g3").bind({})
    with pytest.raises(SpecError, match=r"port 'ref' of aunp_sensor takes samples of shape \(\)"):
        SENSOR(path=path, ports="ref=g1,g2").bind({})
    with pytest.raises(SpecError, match=r"no such file: .*nope\.csv"):
        SENSOR(path=str(tmp_path / "nope.csv")).bind({})
    bad = tmp_path / "bad.csv"
    bad.write_text("t,ref\n0,1\n0.1,x\n")
    with pytest.raises(SpecError, match="not a number in column 'ref'") as e:
        SENSOR(path=str(bad)).bind({})
    assert e.value.where == (str(bad), 3, 5)


def test_h5_streams_by_node_and_port_with_units_checked(tmp_path):
    path = tmp_path / "rec.h5"
    specs = {
        "sensor.r": StreamSpec("float64", (4,), "1", 1000.0),
        "sensor.ref": StreamSpec("float64", (), "1", 1000.0),
        "other.x": StreamSpec("float64", (), "N", 1000.0),
    }
    t = np.arange(100) / 1000.0
    with Recorder(path, specs, {}) as rec:
        rec.write("sensor.r", Chunk(t, np.ones((100, 4))))
        rec.write("sensor.ref", Chunk(t, np.zeros(100)))
        rec.write("other.x", Chunk(t, np.zeros(100)))
    b = SENSOR(path=str(path), node="sensor")
    out = run_source(b, 0.1, tick_s=0.03)
    assert set(out) == {"r", "ref"} and len(out["r"]) == 100
    assert b.ends_at({}) == pytest.approx(0.1)
    with pytest.raises(SpecError, match=r"port 'ref' of aunp_sensor is in '1'; 'other\.x' in .* is in 'N'"):
        SENSOR(path=str(path), ports="ref=other.x", node="sensor").bind({})
    with pytest.raises(
        SpecError, match=r"no stream for port 'r' .*\(streams: sensor\.r, sensor\.ref, other\.x\); map them"
    ):
        SENSOR(path=str(path), need=["r"], node="elsewhere").bind({})


def test_events_cannot_come_from_a_csv(tmp_path):
    nlif = stand_in_class("nlif")
    path = write_csv(tmp_path / "s.csv", ["t", "spikes"], rows(width=1))
    with pytest.raises(
        SpecError, match=r"port 'spikes' of nlif is an event stream, .* replay it from a \.h5"
    ):
        nlif(path=path).bind({})


def test_after_the_end_nothing_is_emitted(tmp_path):
    b = SENSOR(path=write_csv(tmp_path / "log.csv", ["t", "ref"], rows(width=1)), node="sensor")
    b.bind({})
    assert len(b(0.05)["ref"]) == 5
    after = b(1.0)["ref"]
    assert len(after) == 0 and after.data.shape == (0,)
