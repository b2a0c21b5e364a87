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


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_files_written_atomically_get_the_users_umask(tmp_path, umask):
    import os
    import stat

    old = os.umask(umask)
    try:
        with atomic_path(tmp_path / "a.txt") as tmp:
            tmp.write_text("x")
        (tmp_path / "b.txt").write_text("x")  # what a plain open gives
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "a.txt").stat().st_mode)
    assert mode == stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o666 & ~umask
