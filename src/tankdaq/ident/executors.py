"""Where a campaign's units of work run: this process, a local pool forked once the kernels are loaded,
or a Dask cluster; every unit is a pure, picklable function, so the results are the serial ones."""

from __future__ import annotations

import gc
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing import get_context
from typing import Any

from ..errors import InputError, TankdaqError
from .online import prepare_kernels


def executor_map(
    executor: Executor | None, function: Callable[..., Any], *arguments: Sequence[Any]
) -> Iterable[Any]:
    """``function`` over the argument lists, in order: in this process without an executor."""
    return map(function, *arguments) if executor is None else executor.map(function, *arguments)


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
        with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("fork")) as pool:
            # The workers fork now (before the caller starts a progress thread), with the objects
            # loaded so far frozen out of the cyclic garbage collector: a worker's collections then
            # leave the pages it shares with this process unwritten (bench_campaign: a pool of two
            # spent 2.7 s CPU where one process spends 2.3 s; 2.3 s frozen). Thawed once forked.
            gc.freeze()
            try:
                pool.submit(int).result()
            finally:
                gc.unfreeze()
            yield pool


class DaskExecutor(Executor):
    """A Dask cluster as an executor that knows its size (``threads``: the work is cut to it, see
    ``ident.campaign_stream``). Tasks are not hashed (``pure=False``): the client spends no CPU
    tokenizing their arguments, and a chunk submitted twice runs twice."""

    def __init__(self, client: Any) -> None:
        self._executor = client.get_executor(pure=False)
        self.threads = max(1, sum(client.nthreads().values()))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._executor.shutdown(wait=wait)


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
        raise InputError("--executor dask needs the dask extra: pip install 'tankdaq[dask]'") from None
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
