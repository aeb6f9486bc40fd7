"""CSV sensor logs: what is read, and every bad file refused at the line and column of the problem."""

import numpy as np
import pytest

from flowtact.blocks.signal.csv_log import CsvError, read_csv_log

HEAD = "t,a,b\n"


def test_reads_dialects_comments_and_nan(tmp_path):
    p = tmp_path / "ok.csv"
    p.write_bytes(b'\xef\xbb\xbf# t; a; b\r\n0.0; 1; nan\r\n\r\n# a comment\r\n0.5;"2"; 3 # tail\r\n')
    log = read_csv_log(p)
    assert log.names == ("t", "a", "b") and log.data_columns == ("a", "b")
    np.testing.assert_array_equal(log.t, [0.0, 0.5])
    np.testing.assert_array_equal(log.column("a"), [1.0, 2.0])
    assert np.isnan(log.column("b")[0]) and not log.table.flags.writeable
    spaced = tmp_path / "spaced.csv"
    spaced.write_text("t a\n0 1\n1 2\n")
    np.testing.assert_array_equal(read_csv_log(spaced).column("a"), [1, 2])
    header_only = tmp_path / "empty_table.csv"
    header_only.write_text(HEAD)
    assert read_csv_log(header_only).table.shape == (0, 3)


BAD = {
    "binary": (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", 3, 1, r"not a text file \(a NUL byte\)"),
    "latin1": (b"t,a,b\n0,1,2\n0.1,\xb5,2\n", 3, 5, r"byte 0xb5 is not UTF-8 text"),
    "empty": (b"\n\n", 1, 1, r"the file is empty"),
    "no_t": (
        b"time,a\n0,1\n",
        1,
        1,
        r"no 't' column .*\(columns: time, a\); if 'time' is the time in seconds",
    ),
    "dup": (b"t,a,a\n0,1,2\n", 1, 5, r"column 'a' is named twice"),
    "only_t": (b"t\n0\n", 1, 1, r"no data columns besides 't'"),
    "ragged_short": (
        HEAD.encode() + b"0,1,2\n0.1,1\n",
        3,
        5,
        r"2 values in this row, but the header names 3",
    ),
    "ragged_long": (HEAD.encode() + b"0,1,2\n0.1,1,2,9\n", 3, 9, r"4 values in this row"),
    "text": (HEAD.encode() + b"0,1,2\n\n0.1,1,abc\n", 4, 7, r"not a number in column 'b': 'abc'"),
    "empty_cell": (HEAD.encode() + b"0,1,2\n0.1,,2\n", 3, 5, r"an empty cell in column 'a'"),
    "nan_time": (
        HEAD.encode() + b"0,1,2\nnan,1,2\n",
        3,
        1,
        r"time 'nan' in column 't' is not a finite number",
    ),
    "back": (
        HEAD.encode() + b"0,1,2\n# c\n0.2,1,2\n0.1,1,2\n",
        5,
        1,
        r"time goes back: t = 0\.1 s after 0\.2 s",
    ),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_files_are_refused_in_place(tmp_path, case):
    content, line, col, message = BAD[case]
    p = tmp_path / f"{case}.csv"
    p.write_bytes(content)
    with pytest.raises(CsvError, match=message) as e:
        read_csv_log(p)
    assert e.value.where == (str(p), line, col)
    assert str(e.value).startswith(f"{p}:{line}:{col}: ")


def test_a_changed_file_is_read_again(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text(HEAD + "0,1,2\n")
    assert read_csv_log(p).table.shape == (1, 3)
    p.write_text(HEAD + "0,1,2\n0.1,3,4\n")
    assert read_csv_log(p).table.shape == (2, 3)
