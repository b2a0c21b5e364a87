"""eas-vo's own threads: work split or streamed across them gives what one thread gives, in
order; errors come at their turn; a forked child (a compare worker) gets a pool of its own."""

from __future__ import annotations

import multiprocessing
import threading

import pytest

from eas_vo import concurrency


@pytest.fixture
def threads():
    before = concurrency.threads()
    yield concurrency.set_threads
    concurrency.set_threads(before)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_split_and_in_order_give_one_threads_results(threads, n):
    threads(n)
    assert concurrency.split(lambda a, b: list(range(a, b)), 10, 2) == [
        list(range(a, b)) for a, b in _parts(10, min(n, 5))
    ]
    assert list(concurrency.in_order(lambda k: k * k, 20, ahead=3)) == [k * k for k in range(20)]


def _parts(count, parts):
    bounds = [count * p // parts for p in range(parts + 1)]
    return list(zip(bounds, bounds[1:]))


def test_one_thread_runs_in_the_callers_thread(threads):
    threads(1)
    caller = threading.get_ident()
    assert set(concurrency.in_order(lambda k: threading.get_ident(), 5)) == {caller}
    assert concurrency.split(lambda a, b: threading.get_ident(), 100, 1) == [caller]


def test_an_error_comes_at_its_turn_and_later_work_is_dropped(threads):
    threads(2)
    started = []

    def work(k):
        started.append(k)
        if k == 3:
            raise ValueError("k = 3")
        return k

    got = []
    with pytest.raises(ValueError, match="k = 3"):
        for value in concurrency.in_order(work, 1000, ahead=4):
            got.append(value)
    assert got == [0, 1, 2] and len(started) < 20


def _child(queue):
    queue.put(list(concurrency.in_order(lambda k: k + 1, 8)))


def test_a_forked_child_makes_its_own_pool(threads):
    threads(2)
    assert list(concurrency.in_order(lambda k: k, 4)) == [0, 1, 2, 3]  # the parent's pool exists
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_child, args=(queue,))
    child.start()
    child.join(60)
    assert child.exitcode == 0 and queue.get(timeout=5) == list(range(1, 9))


@pytest.mark.parametrize("n", [1, 2])
def test_submit_gives_the_result_or_raises_at_result(threads, n):
    threads(n)
    assert concurrency.submit(lambda a, b: a * b, 6, 7).result() == 42
    failed = concurrency.submit(lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        failed.result()


@pytest.mark.parametrize("n", [1, 2])
def test_ahead_yields_in_order_raises_at_its_turn_and_stops_drawing(threads, n):
    """ahead: the items in order; the iterable's exception after the items before it; a caller
    that stops early leaves the drawing thread stopped, at most `depth` (+1 in hand) drawn."""
    import time

    threads(n)
    assert list(concurrency.ahead(iter(range(50)), depth=3)) == list(range(50))

    def failing():
        yield from range(5)
        raise ValueError("item 5")

    got = []
    with pytest.raises(ValueError, match="item 5"):
        for item in concurrency.ahead(failing()):
            got.append(item)
    assert got == list(range(5))

    drawn = []

    def counted():
        for k in range(1000):
            drawn.append(k)
            yield k

    stream = concurrency.ahead(counted(), depth=2)
    assert [next(stream) for _ in range(3)] == [0, 1, 2]
    stream.close()
    time.sleep(0.1)
    assert len(drawn) <= 3 + 2 + 1
    assert not [t for t in threading.enumerate() if t.name == "eas-vo-ahead"]
