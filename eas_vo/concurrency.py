"""The threads eas-vo's own parallel work runs on: kernels that release the GIL (numba's
`nogil`, OpenCV, cramjam) split across them. As many as the machine has cores, unless a process
that shares the cores with others (a `compare` worker) is given fewer; 1 is the serial path.
Results never depend on the count: work is split into independent parts taken in order."""

from __future__ import annotations

import os
import queue
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Callable, Iterable, Iterator, TypeVar

T = TypeVar("T")

_threads = os.cpu_count() or 1
_pool: ThreadPoolExecutor | None = None


def threads() -> int:
    """How many threads eas-vo's parallel work may use in this process."""
    return _threads


def set_threads(n: int) -> None:
    """Use `n` >= 1 threads from now on (1: everything in the calling thread)."""
    global _threads, _pool
    if n < 1:
        raise ValueError(f"threads must be at least 1, not {n}")
    if n != _threads and _pool is not None:
        _pool.shutdown(wait=True)
        _pool = None
    _threads = n


def _forget_pool() -> None:
    """In a forked child: the parent's pool threads do not exist here; a new pool is made on use."""
    global _pool
    _pool = None


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _shared_pool() -> ThreadPoolExecutor:
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(_threads, thread_name_prefix="eas-vo")
    return _pool


def submit(work: Callable[..., T], *args) -> Future:
    """work(*args) started on the threads (done at once, in the caller's thread, with one)."""
    if _threads > 1:
        return _shared_pool().submit(work, *args)
    return done_now(work, *args)


def done_now(work: Callable[..., T], *args) -> Future:
    """work(*args) done at once in the caller's thread, as a Future (for work whose result is
    waited for at once: a thread would only add its hand-over)."""
    done: Future = Future()
    try:
        done.set_result(work(*args))
    except Exception as exc:  # noqa: BLE001  (raised by result(), as from a thread)
        done.set_exception(exc)
    return done


def in_order(work: Callable[[int], T], count: int, ahead: int = 6) -> Iterator[T]:
    """work(0), ..., work(count - 1), yielded in order, computed on the threads at most `ahead`
    before they are taken (bounded memory); in the caller's thread with one thread. work(k)'s
    exception is raised when k's turn comes; work not yet started is cancelled when the caller stops."""
    if _threads == 1:
        yield from (work(k) for k in range(count))
        return
    pool, pending = _shared_pool(), []
    try:
        for k in range(count):
            pending.append(pool.submit(work, k))
            if len(pending) >= ahead:
                yield pending.pop(0).result()
        while pending:
            yield pending.pop(0).result()
    finally:
        for future in pending:
            future.cancel()


def ahead(items: Iterable[T], depth: int = 2) -> Iterator[T]:
    """The items of `items`, in order, drawn from it on a thread of their own at most `depth`
    ahead of the caller (a reader decoding the next frame while the caller works on this one);
    drawn in the caller's thread with one thread. An exception of the iterable comes at its
    turn; when the caller stops early (an error, Ctrl-C), the thread stops drawing."""
    if _threads == 1:
        yield from items
        return
    done, stop = object(), threading.Event()
    drawn: queue.Queue = queue.Queue(depth)

    def draw():
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        drawn.put((item, None), timeout=0.05)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            drawn.put((done, None))
        except BaseException as exc:  # noqa: BLE001  (raised in the caller, at its turn)
            drawn.put((done, exc))

    thread = threading.Thread(target=draw, name="eas-vo-ahead", daemon=True)
    thread.start()
    try:
        while True:
            item, error = drawn.get()
            if item is done:
                if error is not None:
                    raise error
                return
            yield item
    finally:
        stop.set()
        while thread.is_alive():  # let a blocked put see the stop
            try:
                drawn.get_nowait()
            except queue.Empty:
                thread.join(0.01)


def split(work: Callable[[int, int], T], count: int, min_part: int) -> list[T]:
    """work(start, stop) over [0, count) cut into one part per thread (each at least `min_part`
    long), computed at once; the parts' results in order."""
    parts = max(1, min(_threads, count // max(min_part, 1)))
    bounds = [count * p // parts for p in range(parts + 1)]
    if parts == 1:
        return [work(0, count)]
    return [f.result() for f in [_shared_pool().submit(work, a, b) for a, b in zip(bounds, bounds[1:])]]
