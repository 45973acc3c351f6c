"""One task per item, in this process or on a dask cluster, results in item order.

On the ground floor: the noise design study, the realisation study and the face
run all map their tasks through :func:`map_tasks` (re-exported by
:mod:`servosurf.scale`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

__all__ = ["map_tasks"]


def map_tasks(fn: Callable[[Any], Any], items: Sequence[Any], *, client=None,
              progress: Callable[..., Iterable] | None = None) -> list:
    """``[fn(x) for x in items]``, locally or one dask task per item.

    Parameters
    ----------
    fn : callable
        A picklable function of one item (a module-level function or a
        :func:`functools.partial` of one) when ``client`` is given.
    items : sequence
        The items (picklable with a client).
    client : distributed.Client, optional
        Run every item as its own task on this cluster; default: in this process,
        in order.
    progress : callable, optional
        Wraps the iterable of finished items, called as ``progress(it, total=n)``
        (e.g. :func:`servosurf._progress.bar`).

    Returns
    -------
    list
        ``fn(item)`` for every item, in the order of ``items`` whatever order the
        tasks finish in; the same values as the in-process run for deterministic
        ``fn``.

    Notes
    -----
    Tasks are submitted with ``pure=False`` so that equal items still run as
    separate tasks. A task's exception is raised here, as in the local run.
    """
    items = list(items)
    wrap = progress if progress is not None else (lambda it, total=None: it)
    if client is None:
        return [fn(x) for x in wrap(items, total=len(items))]
    from distributed import as_completed

    futures = client.map(fn, items, pure=False)
    where = {f.key: i for i, f in enumerate(futures)}
    out: list = [None] * len(futures)
    for fut in wrap(as_completed(futures), total=len(futures)):
        out[where[fut.key]] = fut.result()
    return out
