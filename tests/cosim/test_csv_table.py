"""The one CSV-table reader (:func:`cosim.core.csv_table.read_csv_table`): what it reads and
the one-line refusals naming the file, the line and the column."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.core.csv_table import read_csv_table

TWO = [("t", "s")]
GPS = [("t", "x", "y", "z"), ("t", "x", "y", "z", "vx", "vy", "vz")]


def _f(tmp_path, text, name="f.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_rows_with_comments_header_and_separators(tmp_path):
    p = _f(tmp_path, "# a table\n\ntime,range  # header\n0;1 # first\n1,3\n\n2;5,99\n")
    t = read_csv_table(p, "T", TWO, min_rows=3, header=True, separators=",;",
                       extra_columns=True)
    np.testing.assert_array_equal(t.values, [[0, 1], [1, 3], [2, 5]])
    assert t.lines == (4, 5, 7) and t.columns == ("t", "s")
    assert not t.values.flags.writeable
    t7 = read_csv_table(_f(tmp_path, "t,x,y,z,vx,vy,vz\n0,1,2,3,4,5,6\n1,1,2,3,4,5,6\n"), "G",
                        GPS, min_rows=(4, 2), header=True)
    assert t7.values.shape == (2, 7) and t7.columns == GPS[1]


@pytest.mark.parametrize("text,kw,msg", [
    ("0,1\n1,2,3\n", {}, "T line 2: 3 columns; a row is t, s (2 columns) as the first row "
                         "(line 1)"),
    ("0,1,2\n", {}, "T line 1: 3 columns; a row is t, s (2 columns)"),
    ("0,1\n1,inf\n", {}, "T line 2, column 2: 'inf' is not a finite number"),
    ("t,s\n0,1\n", {}, "T line 1, column 1: 't' is not a finite number"),       # no header
    ("t,s\nu,v\n0,1\n", {"header": True}, "T line 2, column 1: 'u' is not a finite number"),
    ("0,1\n1,2\n", {}, "T has 2 rows of (t, s); the table needs at least 3"),
    ("0,1\n2,2\n2,3\n", {}, "T line 3, column 1: time must increase strictly; 2 s does not "
                            "follow 2 s (line 2)"),
    ("0;1\n1;2\n2;3\n", {}, "T line 1: 1 columns; a row is t, s (2 columns)"),   # ',' only
])
def test_refusals_name_the_line_and_column(tmp_path, text, kw, msg):
    with pytest.raises(ValueError) as e:
        read_csv_table(_f(tmp_path, text), "T", TWO, min_rows=3, **kw)
    assert str(e.value) == msg


def test_layouts_and_per_layout_row_minimum(tmp_path):
    with pytest.raises(ValueError, match=r"^G line 1: 5 columns; a row is 4 \(t, x, y, z\) or "
                                         r"7 \(t, x, y, z, vx, vy, vz\) columns$"):
        read_csv_table(_f(tmp_path, "0,1,2,3,4\n"), "G", GPS, min_rows=(4, 2))
    with pytest.raises(ValueError, match=r"has 3 rows of \(t, x, y, z\); the table needs at "
                                         r"least 4$"):
        read_csv_table(_f(tmp_path, "0,1,2,3\n1,1,2,3\n2,1,2,3\n"), "G", GPS, min_rows=(4, 2))
    with pytest.raises(ValueError, match="^G is not a file$"):
        read_csv_table(tmp_path / "none.csv", "G", GPS, min_rows=2)
