"""Core types: window lookups in an event stream."""

import numpy as np

from helpers import random_events


def test_search_times_equals_searchsorted_without_copying(tmp_path):
    from eas_vo.types import search_times

    ev = random_events(100_000, seed=9)
    ev["t"][1000:1010] = ev["t"][1000]  # ties
    queries = np.concatenate([[-1.0, ev["t"][1000], 1e9], np.random.default_rng(0).uniform(0, 1300, 500)])
    np.testing.assert_array_equal(search_times(ev, queries), np.searchsorted(ev["t"], queries, side="left"))
    assert len(search_times(ev[:0], [1.0])) == 1 and search_times(ev[:0], [1.0])[0] == 0

