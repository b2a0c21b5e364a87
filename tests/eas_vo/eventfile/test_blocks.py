"""The compiled block parser: exact times, two threads equal one, unusual lines leave the fast path."""

import numpy as np
import pytest

from eas_vo.eventfile import BlockParser, format_events, parse_block
from helpers import random_events


def test_compiled_parser_equals_python_float_exactly():
    rng = np.random.default_rng(3)
    text = (
        "".join(
            f"{t:.{d}f} {x} {y} {p}\n"
            for t, d, x, y, p in zip(
                rng.uniform(0, 5000, 3000),
                rng.integers(0, 10, 3000),
                rng.integers(0, 240, 3000),
                rng.integers(0, 180, 3000),
                rng.integers(0, 2, 3000),
            )
        )
        + "7 1 2 -1\r\n  \n0.5\t3  4 1"
    )  # integer time, CRLF, -1 polarity, blank line, tabs, no final newline
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


@pytest.mark.parametrize(
    "text",
    [
        "1e-3 1 2 1\n",
        "-0.5 1 2 1\n",
        "0.1 1 2\n",
        "0.1 1 2 1 9\n",
        "0.1 1.5 2 1\n",
        "0.1 1.05 2 1\n",
        ". 1 2 1\n",
        "0.1 .0 2 1\n",
        "10000000000000000.5 1 2 1\n",
    ],
)  # an integer part beyond 2**53 / 10 s
def test_unusual_lines_leave_the_fast_path(text):
    assert parse_block(np.frombuffer(text.encode(), np.uint8)) is None


def _times_of(text: str) -> list[float]:
    return [float(line.split()[0]) for line in text.splitlines() if line.strip()]


def test_unix_times_with_any_number_of_digits_take_the_compiled_path_exactly():
    """Times as events exported from a ROS bag have them (`1700000000.000015736`): the compiled
    parser takes them, each the float64 nearest to its text, like integer parts and fractions
    of other lengths (it may leave a line to the text path only to be sure of the nearest)."""
    rng = np.random.default_rng(8)
    unix = "".join(
        f"{1_700_000_000 + k // 7}.{ns:09d} 239 11 0\n" for k, ns in enumerate(np.sort(rng.integers(0, 10**9, 5000)))
    )
    ev = parse_block(np.frombuffer(unix.encode(), np.uint8), tolerance_s=np.inf)
    assert ev is not None
    np.testing.assert_array_equal(ev["t"], np.maximum.accumulate(_times_of(unix)))  # bit-exact
    taken = 0
    for _ in range(3000):
        integer = str(int(rng.integers(0, 10 ** int(rng.integers(1, 16)))))
        fraction = "".join(map(str, rng.integers(0, 10, int(rng.integers(0, 25)))))
        line = f"{integer}.{fraction} 1 2 1\n" if fraction or rng.random() < 0.5 else f"{integer} 1 2 1\n"
        ev = parse_block(np.frombuffer(line.encode(), np.uint8))
        if ev is not None:
            assert ev["t"][0] == float(line.split()[0]), line
            taken += 1
    assert taken > 2700


def test_times_next_to_a_rounding_tie_are_the_nearest_double():
    """Decimals at, just above and just below the midpoint between two doubles at 1.7e9 s:
    the compiled parser gives the nearest double, or leaves the line to the text path."""
    from decimal import Decimal, getcontext

    getcontext().prec = 60
    base = 1_700_000_000.0
    ulp = Decimal(np.spacing(base))
    lines = []
    for k in range(300):
        middle = Decimal(base) + ulp * k + ulp / 2
        lines += [f"{middle + Decimal(eps):f} 1 2 1\n" for eps in ("0", "1e-25", "-1e-25", "1e-12", "-1e-12")]
    for line in lines:
        ev = parse_block(np.frombuffer(line.encode(), np.uint8))
        assert ev is None or ev["t"][0] == float(line.split()[0]), line


def test_whole_pixel_coordinates_written_with_a_fraction_stay_on_the_fast_path():
    text = "0.5 120.0 33.0 1\n0.6 120. 33 1.0\n0.7 7 8.000 -1.0\n"
    ev = parse_block(np.frombuffer(text.encode(), np.uint8))
    assert ev is not None
    assert ev["x"].tolist() == [120, 120, 7] and ev["y"].tolist() == [33, 33, 8] and ev["p"].tolist() == [1, 1, 0]
