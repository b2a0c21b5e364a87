"""Numeric text tables and atomic writes."""

import numpy as np
import pytest

from eas_vo.errors import DataError
from eas_vo.io import atomic_path, read_table


def test_read_table_skips_comments_and_blank_lines(tmp_path):
    path = tmp_path / "t.txt"
    path.write_text("# header\n1 2 3\n\n4 5 6\n")
    np.testing.assert_array_equal(read_table(path, 3, "a b c"), [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("text,line", [("1 2 3\n4 5\n", 2), ("1 2 3\n4 x 6\n", 2), ("1 2 inf\n", 1)])
def test_read_table_names_the_bad_line(tmp_path, text, line):
    path = tmp_path / "t.txt"
    path.write_text(text)
    with pytest.raises(DataError) as info:
        read_table(path, 3, "a b c")
    assert info.value.line == line


def test_atomic_path_leaves_the_old_file_on_failure(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert path.read_text() == "old" and list(tmp_path.iterdir()) == [path]
