"""The compiled block parser: exact times, two threads equal one, unusual lines leave the fast path."""


import numpy as np
import pytest

from eas_vo.eventfile import BlockParser, format_events, parse_block
from helpers import random_events


def test_compiled_parser_equals_python_float_exactly():
    rng = np.random.default_rng(3)
    text = "".join(
        f"{t:.{d}f} {x} {y} {p}\n"
        for t, d, x, y, p in zip(rng.uniform(0, 5000, 3000), rng.integers(0, 10, 3000), rng.integers(0, 240, 3000),
                                 rng.integers(0, 180, 3000), rng.integers(0, 2, 3000))
    ) + "7 1 2 -1\r\n  \n0.5\t3  4 1"  # integer time, CRLF, -1 polarity, blank line, tabs, no final newline
    ev = parse_block(np.frombuffer(text.encode(), np.uint8), tolerance_s=np.inf)
    rows = [line.split() for line in text.splitlines() if line.strip()]
    t = np.maximum.accumulate([float(r[0]) for r in rows])  # steps back are clamped
    np.testing.assert_array_equal(ev["t"], t)  # bit-exact
    np.testing.assert_array_equal(ev["x"], [int(r[1]) for r in rows])
    np.testing.assert_array_equal(ev["y"], [int(r[2]) for r in rows])
    np.testing.assert_array_equal(ev["p"], [int(r[3]) > 0 for r in rows])


def test_parser_in_two_threads_equals_one():
    ev = random_events(200_000, seed=4)
    buf = np.frombuffer(format_events(ev), np.uint8)
    parser = BlockParser(240, 180, 1e-6, threads=2)
    pieces = parser(buf)
    parser.close()
    assert len(pieces) == 2 and all(packed is not None for _, packed in pieces)
    np.testing.assert_array_equal(np.concatenate([packed[0] for _, packed in pieces]), parse_block(buf))
    np.testing.assert_allclose(parse_block(buf)["t"], ev["t"], atol=5e-10)


@pytest.mark.parametrize("text", ["1e-3 1 2 1\n", "-0.5 1 2 1\n", "0.1 1 2\n", "0.1 1 2 1 9\n", "0.1 1.5 2 1\n"])
def test_unusual_lines_leave_the_fast_path(text):
    assert parse_block(np.frombuffer(text.encode(), np.uint8)) is None

