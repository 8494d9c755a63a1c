"""Where units of work run: in this process, on local worker processes, or on Ray.

A backend maps a picklable top-level function over a list of argument tuples and yields
``(index, result)`` as results finish, in any order; the caller saves them (see
:mod:`.engine`). Results must depend only on the arguments, so every backend gives the same
rows. A backend is a context manager: leaving it, normally or by an exception (including
``KeyboardInterrupt`` and a SIGTERM turned into one), stops every worker it started.

- :class:`LocalBackend` (``workers`` processes, ``spawn``): each worker watches its parent and
  exits within a fraction of a second once the parent is gone, even after ``kill -9`` of the
  parent (no orphans, and the multiprocessing resource tracker, which lives as long as any
  process holds its pipe, goes with them).
- :class:`RayBackend`: tasks on an existing cluster (``address``) or on a local Ray started
  with ``cpus`` CPUs. Ray retries a task whose worker died (``max_retries``); the store drops
  a run key it already has, so a retry never duplicates a row. At most a few tasks per CPU
  are in flight, so a long sweep does not flood the object store; Ray does the scheduling.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence

from airspace_sim.errors import UserError

BACKENDS = ("local", "ray")

#: Worker threads of numerical libraries: one per process, the processes are the parallelism.
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def worker_env() -> dict[str, str]:
    """The thread variables a worker gets (local process or Ray task, on this machine or a
    cluster's): this process's value where the user set one, else ``"1"``. Only the workers
    get them: this process's environment is never changed."""
    return {v: os.environ.get(v, "1") for v in _THREAD_VARS}


def _init_worker(parent_pid: int, env: dict[str, str]) -> None:
    """Worker initializer: ``env`` into this worker's environment (before the unit's
    function, and with it numpy and numba, is imported: they read the thread variables
    when loaded), then :func:`_watch_parent`."""
    os.environ.update(env)
    _watch_parent(parent_pid)


def _watch_parent(parent_pid: int, period_s: float = 0.2) -> None:
    """Exit this process as soon as ``parent_pid`` is no longer its parent (it died and
    the worker was re-parented)."""

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(period_s)
        os._exit(70)  # no cleanup: the parent that wanted the result is gone

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


class LocalBackend:
    """``workers`` local processes (1 = run in this process, no pool). If a worker dies, the
    units not finished run again on a new pool, up to ``max_retries`` times."""

    name = "local"

    def __init__(self, workers: int = 1, max_retries: int = 2):
        self.workers = int(workers)
        self.max_retries = int(max_retries)
        self._pool = None
        self._procs: list = []

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def imap(self, fn: Callable, args: Sequence[tuple]) -> Iterator[tuple[int, object]]:
        if self.workers == 1 or len(args) <= 1:
            for i, a in enumerate(args):
                yield i, fn(*a)
            return
        from concurrent.futures.process import BrokenProcessPool

        todo = dict(enumerate(args))
        for attempt in range(self.max_retries + 1):
            try:
                for i, result in self._run_pool(fn, todo):
                    del todo[i]
                    yield i, result
                return
            except BrokenProcessPool:
                # a worker died (killed, out of memory): the pool is unusable; a new one
                # runs what has not come back, like Ray's task retries
                self.close()
                if attempt == self.max_retries:
                    raise UserError(
                        f"--workers: a worker process died {attempt + 1} times (killed, or out "
                        "of memory?); the finished runs are saved: rerun to resume, or use "
                        "fewer --workers"
                    ) from None

    def _run_pool(self, fn: Callable, todo: dict) -> Iterator[tuple[int, object]]:
        import multiprocessing as mp
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        before = set(mp.active_children())
        self._pool = ProcessPoolExecutor(
            max_workers=min(self.workers, len(todo)),
            mp_context=mp.get_context("spawn"),
            initializer=_init_worker,
            initargs=(os.getpid(), worker_env()),
        )
        pending = {self._pool.submit(fn, *a): i for i, a in todo.items()}
        self._procs = [p for p in mp.active_children() if p not in before]
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            self._procs = [p for p in mp.active_children() if p not in before]
            for f in finished:
                yield pending.pop(f), f.result()
        self._pool.shutdown(wait=True)
        self._pool = None

    def close(self) -> None:
        """Stop the pool; on an early exit, terminate its workers rather than wait for them."""
        if self._pool is None:
            return
        self._pool.shutdown(wait=False, cancel_futures=True)
        for p in self._procs:
            if p.is_alive():
                p.terminate()
        for p in self._procs:
            p.join(timeout=5)
        self._pool = None


class RayBackend:
    """Ray tasks: on the cluster at ``address``, or on a local Ray with ``cpus`` CPUs.

    A Ray this backend starts is shut down when it closes; one already running (e.g. a
    test's, or ``ray.init`` by the caller) is used and left running."""

    name = "ray"

    def __init__(self, address: str | None = None, cpus: int | None = None, max_retries: int = 3):
        try:
            import ray
        except ImportError:
            raise UserError(
                "--backend ray: Ray is not installed; pip install 'airspace-sim[ray]'"
            ) from None
        self.ray = ray
        self.max_retries = int(max_retries)
        self._owned = False
        self._refs: dict = {}
        if not ray.is_initialized():
            from airspace_sim import registry

            # the workers load the same plugins as this process (Ray workers' cwd differs)
            folders = [str(p.resolve()) for p in registry.plugin_folders() if p.is_dir()]
            env = worker_env()
            if folders:
                env["AIRSPACE_SIM_PLUGINS"] = os.pathsep.join(folders)
            kwargs = dict(
                include_dashboard=False,
                log_to_driver=False,
                configure_logging=False,
                runtime_env={"env_vars": env},
            )
            try:
                if address:
                    ray.init(address=address, **kwargs)
                else:
                    ray.init(num_cpus=int(cpus) if cpus else None, **kwargs)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                where = f"--address {address}" if address else "--backend ray"
                first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
                cause = exc.__cause__  # e.g. an AuthenticationError behind "failed to connect"
                if cause is not None and str(cause).strip():
                    first += (
                        f" ({type(cause).__name__}: {str(cause).strip().splitlines()[0][:160]})"
                    )
                raise UserError(f"{where}: cannot start or reach Ray: {first}") from None
            self._owned = True
        self.cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def imap(self, fn: Callable, args: Sequence[tuple]) -> Iterator[tuple[int, object]]:
        ray = self.ray
        task = ray.remote(num_cpus=1, max_retries=self.max_retries)(fn)
        window = 4 * self.cpus
        todo = iter(enumerate(args))
        refs = self._refs
        for i, a in todo:
            refs[task.remote(*a)] = i
            if len(refs) >= window:
                break
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            for r in ready:
                i = refs.pop(r)
                try:
                    result = ray.get(r)
                except ray.exceptions.RayTaskError as exc:
                    cause = getattr(exc, "cause", None)
                    raise (cause if isinstance(cause, Exception) else exc) from None
                for j, a in todo:
                    refs[task.remote(*a)] = j
                    break
                yield i, result

    def close(self) -> None:
        for r in list(self._refs):
            try:
                self.ray.cancel(r, force=True)
            except Exception:  # noqa: BLE001 - best effort on the way out
                pass
        self._refs.clear()
        if self._owned:
            self.ray.shutdown()
            self._owned = False


def make_backend(name: str = "local", workers: int = 1, address: str | None = None):
    """The backend called ``name`` (``local`` or ``ray``); ``workers`` processes or CPUs."""
    if name not in BACKENDS:
        raise UserError(f"--backend: must be one of {', '.join(BACKENDS)}, got {name!r}")
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise UserError(f"--workers: must be a positive integer, got {workers!r}")
    if name == "local":
        if address:
            raise UserError("--address: only with --backend ray")
        return LocalBackend(workers)
    return RayBackend(address=address, cpus=workers if not address else None)
