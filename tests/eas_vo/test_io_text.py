"""Text tables as editors leave them: a byte-order mark and CRLF line ends read as plain text."""

import numpy as np

from eas_vo.io.tables import parse_table


def test_a_byte_order_mark_and_crlf_line_ends_read_as_plain_text():
    plain = b"# t x\n0.5 1\n0.75 2\n"
    edited = b"\xef\xbb\xbf" + plain.replace(b"\n", b"\r\n")
    np.testing.assert_array_equal(parse_table(edited, "t.txt", 2, "t x"), parse_table(plain, "t.txt", 2, "t x"))
    np.testing.assert_array_equal(parse_table(b"\xef\xbb\xbf0.5 1\n", "t.txt", 2, "t x"), [[0.5, 1.0]])
