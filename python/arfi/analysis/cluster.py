"""A dask.distributed client for the studies that run as tasks (``arfi sweep``, ``arfi envelope``):
on an existing cluster at a scheduler's address, or on a local cluster of worker processes."""

from __future__ import annotations

import os
from typing import Any


def distributed(verb: str) -> Any:
    """The ``dask.distributed`` module, or a ``ValueError`` naming the extra that installs it."""
    try:
        import dask.distributed
    except ImportError:
        raise ValueError(
            f'{verb}: needs dask.distributed, which arfi installs as an extra: pip install "arfi[cluster]"'
        ) from None
    return dask.distributed


def refuse_unreachable(scheduler: str) -> None:
    """A ``ValueError`` at once when nothing listens at a ``tcp://host:port`` scheduler (dask's
    client would retry until its 10 s timeout); other addresses are left to dask."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(scheduler)
    if parts.scheme != "tcp" or parts.hostname is None or parts.port is None:
        return
    try:
        socket.create_connection((parts.hostname, parts.port), timeout=10.0).close()
    except OSError as e:
        raise ValueError(f"scheduler: cannot connect to {scheduler} ({e})") from None


def client_on(scheduler: str | None, workers: int, verb: str, threads_per_worker: int = 1) -> tuple[Any, Any]:
    """A client on the cluster at ``scheduler``, or on a new local cluster of ``workers`` worker
    processes, each running one task at a time with ``threads_per_worker`` threads for arfi's own
    parallel loops (``RAYON_NUM_THREADS``); returns the client and the local cluster (None for an
    existing one), both to be closed."""
    dd = distributed(verb)
    if scheduler:
        refuse_unreachable(scheduler)
        try:
            return dd.Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as e:
            raise ValueError(f"scheduler: cannot connect to {scheduler} ({e})") from None
    if not 1 <= workers <= 256:
        raise ValueError(f"workers: must be between 1 and 256, got {workers}")
    threads = max(1, int(threads_per_worker))
    cluster = dd.LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        env={"RAYON_NUM_THREADS": str(threads)},
    )
    return dd.Client(cluster), cluster


def threads_each(workers: int) -> int:
    """The cores of this machine shared among ``workers`` local worker processes (at least 1)."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))
