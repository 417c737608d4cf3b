"""Where a campaign's units of work run: this process, a local pool forked once the kernels are loaded,
or a Dask cluster; every unit is a pure, picklable function, so the results are the serial ones."""

from __future__ import annotations

import gc
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing import get_context
from typing import Any, TypeVar

from ..errors import InputError, TankdaqError, install_hint
from ..live.preparation import prepare_kernels

T = TypeVar("T")


def executor_map(
    executor: Executor | None, function: Callable[..., Any], *arguments: Sequence[Any]
) -> Iterable[Any]:
    """``function`` over the argument lists, in order: in this process without an executor."""
    return map(function, *arguments) if executor is None else executor.map(function, *arguments)


def send_once(executor: Executor | None, objects: Sequence[Any]) -> list[Any]:
    """``objects`` as arguments for many tasks, each sent once: on a Dask cluster scattered to it (the
    tasks get handles the workers resolve; a report's figures share each group's fit, 25 MB at 360
    decays, which went out once per figure inside the graph); elsewhere the objects themselves."""
    if isinstance(executor, DaskExecutor):
        return executor.scatter(objects)
    return list(objects)


@contextmanager
def campaign_executor(
    jobs: int = 1, scheduler: str | None = None, prepare: Sequence[Callable[[], None]] = ()
) -> Iterator[Executor | None]:
    """Where a campaign's reading, fits and plots run: here (``jobs`` 1), a local process pool of
    ``jobs`` workers, or a Dask cluster at ``scheduler`` (``pip install tankdaq[dask]``).

    A local pool forks its workers from this process once the compiled kernels and whatever
    ``prepare`` loads (e.g. ``viz.campaign_report.load_plotting``) are loaded here: each worker then
    starts with them instead of importing and loading them again, once per worker.
    """
    if scheduler is not None:
        with _dask_client(scheduler) as client:
            yield DaskExecutor(client)
    elif jobs <= 1:
        yield None
    else:
        prepare_kernels()
        for load in prepare:
            load()
        with LocalPool(jobs) as pool:
            # The workers fork now (before the caller starts a progress thread), with the objects
            # loaded so far frozen out of the cyclic garbage collector: a worker's collections then
            # leave the pages it shares with this process unwritten, which copying them would cost in CPU
            # (``bench/bench_campaign.py``). Thawed once forked.
            gc.freeze()
            try:
                pool.submit(int).result()
            finally:
                gc.unfreeze()
            yield pool


class LocalPool(ProcessPoolExecutor):
    """A local pool of ``workers`` processes forked from this one, that knows its size (the work is cut
    to it, see ``campaign.stream``)."""

    def __init__(self, workers: int) -> None:
        super().__init__(max_workers=workers, mp_context=get_context("fork"))
        self.workers = workers


class DaskExecutor(Executor):
    """A Dask cluster as an executor that knows its size (``threads``: the work is cut to it, see
    ``campaign.stream``). Tasks are not hashed (``pure=False``): the client spends no CPU
    tokenizing their arguments, and a chunk submitted twice runs twice.

    A pass of a campaign goes out as one message (``completed``), and this client's own batching of
    what it sends the scheduler is cut from distributed's 10 ms to ``CLIENT_BATCH_S``: a campaign sends
    a handful of messages, and each one that followed another within 10 ms would wait for the rest of
    the batch. Only this client's
    side of its own connection changes; the cluster is left as it was.
    """

    def __init__(self, client: Any) -> None:
        self._client = client
        self._executor = client.get_executor(pure=False)
        self.threads = max(1, sum(client.nthreads().values()))
        stream: Any = getattr(client, "scheduler_comm", None)
        if isinstance(getattr(stream, "interval", None), float):
            stream.interval = min(stream.interval, CLIENT_BATCH_S)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
        return self._executor.submit(fn, *args, **kwargs)

    def completed(
        self, function: Callable[..., T], tasks: Sequence[tuple[Any, ...]]
    ) -> Iterator[tuple[int, T]]:
        """(task index, result) of each task as it completes, the tasks sent in one message and the
        results gathered as they come; what has not started when the consumer stops never will."""
        from distributed import as_completed

        if not tasks:
            return
        futures = self._client.map(function, *zip(*tasks, strict=True), pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        try:
            for future, result in as_completed(futures, with_results=True):
                yield index[future.key], result
        finally:
            self._client.cancel(futures)

    def scatter(self, objects: Sequence[Any]) -> list[Any]:
        """Each object sent to the cluster once; its handle (a Dask future) in its place."""
        return list(self._client.scatter(list(objects), hash=False)) if objects else []

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._executor.shutdown(wait=wait)


#: How long this Dask client holds a message to the scheduler for others to go with it (distributed's
#: own is 10 ms): a campaign's client sends few messages, each the start of a pass the workers wait on.
CLIENT_BATCH_S = 0.001


#: How long a Dask scheduler has to answer before the campaign gives up (one line, exit 1).
DASK_CONNECT_TIMEOUT_S = 5.0


def check_scheduler(scheduler: str) -> None:
    """A Dask scheduler address understood (else one line, exit 2) and answering within
    ``DASK_CONNECT_TIMEOUT_S`` (else one line, exit 1): checked before the campaign starts any work. The
    port is tried with a plain socket: a ``Client`` that failed to connect still tries to close itself
    at exit, loudly."""
    import contextlib
    import socket

    try:
        from distributed.comm import get_address_host_port, parse_address
    except ImportError:
        raise InputError(
            f"--executor dask needs the dask extra (distributed): {install_hint('dask')}"
        ) from None
    try:
        parse_address(scheduler, strict=True)
    except (ValueError, TypeError) as exc:
        raise InputError(
            f"--scheduler {scheduler!r} not understood ({exc}); give e.g. tcp://10.0.0.5:8786"
        ) from None
    try:
        with contextlib.suppress(ValueError):  # an address without host and port (inproc://) is not tried
            socket.create_connection(get_address_host_port(scheduler), timeout=DASK_CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise TankdaqError(_unreachable(scheduler, exc)) from None


def _unreachable(scheduler: str, exc: BaseException) -> str:
    return (
        f"cannot reach the Dask scheduler at {scheduler} within {DASK_CONNECT_TIMEOUT_S:g} s ({exc}); "
        "start it (dask scheduler) or check --scheduler"
    )


@contextmanager
def _dask_client(scheduler: str) -> Iterator[Any]:
    """A Dask client of ``scheduler`` (``check_scheduler`` first), connected within the bound."""
    check_scheduler(scheduler)
    from distributed import Client

    try:
        client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise TankdaqError(_unreachable(scheduler, exc)) from None
    with client:
        yield client
