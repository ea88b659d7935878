"""Engines: run EpisodeTasks on workers and hand each result row to a callback, in completion order.

- ``local``: a process pool (``spawn`` start method: fresh interpreters, like Ray's workers) with ``workers``
  processes. A worker that dies (segfault, out of memory, killed) breaks the pool: the episodes that were in
  flight are then run again one at a time, each in its own one-process pool, so only the episode that kills its
  worker is recorded as an error; the others get their real results.
- ``ray``: the same tasks as Ray tasks (1 CPU each), on a local Ray instance (``address=None``; ``workers`` CPUs)
  or on an existing cluster (``address``, e.g. ``ray://head:10001`` or ``auto``). Every node of a cluster needs
  bigcbf and its dependencies installed (the same version as the driver).

Both hand the tasks out longest first (:func:`bigcbf.bench.tasks.longest_first`: the estimated work of
``bigcbf.cost``, from the scenario's time limit, scene, perception and method), so the pool does not end waiting on
a long episode started last, and both keep at most ``2 * workers`` tasks in flight, so a killed run has started few episodes that it did not
finish, and both send the same top-level function :func:`bigcbf.bench.tasks.guarded`, so the engine cannot change
an episode's result.
"""
from __future__ import annotations

import multiprocessing
import os
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Sequence

from ..errors import UserError
from .tasks import EpisodeTask, error_row, guarded, longest_first, run_episode, watch_parent

OnRow = Callable[[dict], None]
EpisodeFn = Callable[[EpisodeTask], dict]

ENGINES = ("local", "ray")

#: One BLAS/OpenMP thread per worker process: the workers already use every core.
_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _pool(workers: int) -> ProcessPoolExecutor:
    for k in _THREAD_ENV:   # inherited by the spawned workers before they import numpy
        os.environ.setdefault(k, "1")
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=watch_parent, initargs=(os.getpid(),))


def _kill(pool: ProcessPoolExecutor) -> None:
    """Stop the pool now: cancel queued tasks and terminate our worker processes (they hold no results)."""
    procs = list(getattr(pool, "_processes", {}).values())  # the executor has no public terminate in 3.11
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()


def run_local(tasks: Sequence[EpisodeTask], workers: int, on_row: OnRow, fn: EpisodeFn = run_episode) -> None:
    """Run ``tasks`` on a local process pool of ``workers`` processes; ``on_row(row)`` as each one ends."""
    pending = deque(tasks)
    suspects: list[EpisodeTask] = []
    fresh_breaks = 0
    while pending or suspects:
        if suspects:   # a worker died: find which episode killed it by running each suspect alone
            task = suspects.pop(0)
            pool = _pool(1)
            try:
                on_row(pool.submit(guarded, fn, task).result())
            except BrokenProcessPool as exc:
                on_row(error_row(task, f"worker process died while running this episode ({exc})"))
            except BaseException:
                _kill(pool)
                raise
            pool.shutdown(wait=True)
            continue
        pool = _pool(workers)
        inflight: dict = {}
        try:
            while pending or inflight:
                while pending and len(inflight) < 2 * workers:
                    task = pending.popleft()
                    try:
                        inflight[pool.submit(guarded, fn, task)] = task
                    except BrokenProcessPool:       # a worker died since the last wait: this task never started
                        pending.appendleft(task)
                        break
                if not inflight:                    # the pool broke with nothing in flight: start a new one
                    fresh_breaks += 1
                    if fresh_breaks > 3:
                        raise RuntimeError("the local process pool breaks before any episode starts")
                    break
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                broken = False
                for fut in done:
                    task = inflight.pop(fut)
                    try:
                        row = fut.result()
                    except BrokenProcessPool:
                        suspects.append(task)
                        broken = True
                        continue
                    on_row(row)
                    fresh_breaks = 0
                if broken:
                    suspects.extend(inflight.values())
                    inflight.clear()
                    break
        except BaseException:
            _kill(pool)
            raise
        if suspects or pending:
            _kill(pool)
        else:
            pool.shutdown(wait=True)


def ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def run_ray(tasks: Sequence[EpisodeTask], workers: int | None, on_row: OnRow, fn: EpisodeFn = run_episode,
            address: str | None = None) -> None:
    """Run ``tasks`` as Ray tasks; ``on_row(row)`` as each one ends.

    ``address=None`` starts a local Ray instance with ``workers`` CPUs (default: all cores) and stops it at the
    end; with an address, connects to that cluster and keeps at most ``2 * workers`` tasks in flight (default:
    twice the cluster's CPUs). A task whose Ray worker dies is recorded as an error row.
    """
    try:
        import ray
    except ImportError:
        raise UserError("--engine ray needs Ray: pip install 'bigcbf[ray]'") from None
    started = False
    if not ray.is_initialized():
        kwargs = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        try:
            if address is None:
                ray.init(num_cpus=workers or os.cpu_count(), **kwargs)
            else:
                ray.init(address=address, **kwargs)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise UserError(f"cannot start or reach Ray{f' at {address}' if address else ''}: {exc}") from None
        started = True
    try:
        if workers is None:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(num_cpus=1, max_retries=0)(guarded)
        pending = deque(tasks)
        inflight: dict = {}
        try:
            while pending or inflight:
                while pending and len(inflight) < 2 * workers:
                    task = pending.popleft()
                    inflight[remote.remote(fn, task)] = task
                ready, _ = ray.wait(list(inflight), num_returns=1)
                for ref in ready:
                    task = inflight.pop(ref)
                    try:
                        row = ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        row = error_row(task, f"Ray task failed: {type(exc).__name__}: {str(exc).splitlines()[0]}")
                    on_row(row)
        except BaseException:
            for ref in inflight:
                ray.cancel(ref, force=True)
            raise
    finally:
        if started:
            ray.shutdown()


def run(engine: str, tasks: Sequence[EpisodeTask], workers: int | None, on_row: OnRow,
        fn: EpisodeFn = run_episode, ray_address: str | None = None) -> None:
    """Dispatch to :func:`run_local` or :func:`run_ray`, the tasks longest first."""
    if engine in ENGINES:
        tasks = longest_first(list(tasks))
    if engine == "local":
        run_local(tasks, workers or os.cpu_count() or 1, on_row, fn)
    elif engine == "ray":
        run_ray(tasks, workers, on_row, fn, ray_address)
    else:
        raise UserError(f"unknown engine {engine!r}; known: {', '.join(ENGINES)}")
