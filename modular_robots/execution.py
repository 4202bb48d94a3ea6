"""Where work runs: in this process or on a pool of worker processes.

Both engines map a function over a stream of items in chunks and yield the results in input
order, with a bounded number of chunks in flight (memory stays bounded however long the
stream). A distributed engine (e.g. Ray) only has to provide :meth:`Engine.map_chunks`.
"""

from __future__ import annotations

import itertools
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Protocol, TypeVar

__all__ = ["Engine", "SerialEngine", "ProcessEngine", "make_engine", "available_cores"]

T = TypeVar("T")
R = TypeVar("R")


class Engine(Protocol):
    """Runs ``work(context, chunk)`` over chunks of ``items``; results come back in order."""

    jobs: int

    def map_chunks(
        self, work: Callable[[Any, list[T]], list[R]], context: Any, items: Iterable[T], chunksize: int = 16
    ) -> Iterator[R]: ...


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _chunks(items: Iterable[T], size: int) -> Iterator[list[T]]:
    iterator = iter(items)
    while chunk := list(itertools.islice(iterator, size)):
        yield chunk


class SerialEngine:
    """Everything in the calling process (``--jobs 1``): simplest to debug and profile."""

    jobs = 1

    def map_chunks(self, work, context, items, chunksize=16):
        for chunk in _chunks(items, chunksize):
            yield from work(context, chunk)


_CONTEXT: Any = None


def _set_context(context: Any) -> None:
    global _CONTEXT
    _CONTEXT = context


def _run_in_worker(work: Callable, chunk: list) -> list:
    return work(_CONTEXT, chunk)


class ProcessEngine:
    """A pool of ``jobs`` worker processes; the context is sent once to each worker.

    At most ``jobs * window`` chunks are in flight, so a long stream is never materialised.
    """

    def __init__(self, jobs: int | None = None, window: int = 16):
        self.jobs = jobs or available_cores()
        self.window = window

    def map_chunks(self, work, context, items, chunksize=16):
        with ProcessPoolExecutor(self.jobs, initializer=_set_context, initargs=(context,)) as pool:
            pending: deque = deque()
            try:
                for chunk in _chunks(items, chunksize):
                    pending.append(pool.submit(_run_in_worker, work, chunk))
                    if len(pending) >= self.jobs * self.window:
                        yield from pending.popleft().result()
                while pending:
                    yield from pending.popleft().result()
            finally:
                for future in pending:
                    future.cancel()


def make_engine(jobs: int | None = None) -> Engine:
    """``jobs`` = 1: :class:`SerialEngine`; ``None`` or 0: every available core."""
    jobs = jobs or available_cores()
    return SerialEngine() if jobs == 1 else ProcessEngine(jobs)
