"""Work spread over a :class:`concurrent.futures.Executor`: local processes on every core by
default, or a cluster's (Dask ``distributed``: ``Client(...).get_executor()``; Ray through an
executor adapter). The blind validation campaigns (:mod:`rollest.campaign`) and the SIL sweeps
(:mod:`rollest.closed_loop`) submit their units of work here, a bounded number at a time, so the
coordinating process holds only the inputs in flight.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from typing import Any, Callable, Dict, Iterable, List, Optional, Set, Tuple, TypeVar

#: ``progress(done, total)``, called in the coordinating process as each unit of work comes back.
CampaignProgress = Callable[[int, int], object]

R = TypeVar("R")


def _one_thread_each() -> None:
    """Initializer of the default local workers: one engine thread per process (as many
    processes as cores), so the processes do not oversubscribe the cores."""
    os.environ["RAYON_NUM_THREADS"] = "1"


def local_executor(max_workers: Optional[int] = None) -> ProcessPoolExecutor:
    """Local processes on every core (``max_workers`` when given), started fresh (``spawn``:
    the engine's threads do not survive a ``fork``). A script that uses it guards its entry
    point with ``if __name__ == "__main__":``, as every ``spawn`` pool requires."""
    return ProcessPoolExecutor(
        max_workers=max_workers or os.cpu_count() or 1,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_one_thread_each,
    )


def default_in_flight(max_in_flight: Optional[int]) -> int:
    """How many units are out at once: ``max_in_flight``, or twice the local cores."""
    return max_in_flight or 2 * (os.cpu_count() or 1)


def run_bounded(
    pool: Executor,
    work: Iterable[Tuple[int, Callable[..., R], Tuple[Any, ...]]],
    total: int,
    in_flight: int,
    progress: Optional[CampaignProgress] = None,
) -> List[Tuple[int, R]]:
    """Submits each ``(key, function, arguments)`` of ``work`` to ``pool``, at most
    ``in_flight`` at once (``work`` is drawn only as room frees up), and returns every
    ``(key, result)`` in the order of the keys. The first exception a unit raises is raised
    here, and the units not yet started are cancelled."""
    pending: Dict[Future[R], int] = {}
    done: List[Tuple[int, R]] = []

    def collect(finished: Set[Future[R]]) -> None:
        for future in finished:
            done.append((pending.pop(future), future.result()))
            if progress is not None:
                progress(len(done), total)

    try:
        for key, function, arguments in work:
            while len(pending) >= in_flight:
                finished, _ = wait(set(pending), return_when=FIRST_COMPLETED)
                collect(finished)
            pending[pool.submit(function, *arguments)] = key
        while pending:
            finished, _ = wait(set(pending), return_when=FIRST_COMPLETED)
            collect(finished)
    finally:
        for future in pending:
            future.cancel()
    return sorted(done, key=lambda item: item[0])


class RayExecutor(Executor):
    """A Ray cluster as a :class:`concurrent.futures.Executor`: each call becomes a Ray task,
    and Ray's ``ObjectRef.future()`` is already a :class:`concurrent.futures.Future`. Connect
    first (``ray.init(address="auto")``); Ray is not a dependency of this package."""

    def submit(self, fn: Callable[..., R], /, *args: Any, **kwargs: Any) -> "Future[R]":
        ray = importlib.import_module("ray")  # imported when used: not a dependency
        future: "Future[R]" = ray.remote(fn).remote(*args, **kwargs).future()
        return future
