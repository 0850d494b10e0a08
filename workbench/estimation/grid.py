"""Measurement nodes at their own time tags: merge a propagation grid with measurement times.

A filter propagates over a base grid (e.g. the IMU samples, times ``t`` (n,) [s]) and applies
measurements whose time tags fall between the grid steps.  Rather than moving a measurement to
the nearest step (a time-tag error of up to half a step), :func:`merge_time_tags` inserts a node
at the tag: the filter propagates to the tag, updates, and propagates on to the next base step,
with the inputs of the base interval interpolated at the node (``fraction``).  Tags within
``tol`` of a base step are applied at that step (*snapped*: no node is inserted), tags within
``tol`` of an already inserted node of the same interval share it, and tags that fall in an
interval where no node may be inserted (``no_insert``, e.g. a data gap bridged without inputs)
are applied at the nearer end of that interval.  Tags outside ``[t[0] − tol, t[-1] + tol]`` are
dropped (node −1).

The merged grid is strictly increasing and contains every base step, so the filter's and the
smoother's recursions run on it unchanged; a caller drops the inserted nodes from the histories
it reports with ``base_node >= 0``.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["MergedGrid", "merge_time_tags"]


@dataclass(frozen=True)
class MergedGrid:
    """Result of :func:`merge_time_tags` for a base grid of n steps, m tags and N merged nodes.

    ``t`` (N,) [s] strictly increasing merged times (every base time, plus the inserted nodes);
    ``interval`` (N,) int: for a base node its base index k, for an inserted node the index i of
    the base interval ``(t[i], t[i+1])`` it lies in; ``base_node`` (N,) int base index or −1 for an
    inserted node; ``fraction`` (N,) ``(t_node − t[i]) / (t[i+1] − t[i])`` in (0, 1) for an
    inserted node, 0 for a base node (the weight of linear input interpolation);
    ``tag_node`` (m,) int merged node of each tag (−1: outside the span, dropped);
    ``tag_snapped`` (m,) bool tag applied at a base step within ``tol``; ``tag_moved`` (m,) bool
    tag in a ``no_insert`` interval applied at the nearer end; counts ``n_outside``,
    ``n_snapped``, ``n_moved``, ``n_inserted`` (inserted nodes).
    """

    t: np.ndarray
    interval: np.ndarray
    base_node: np.ndarray
    fraction: np.ndarray
    tag_node: np.ndarray
    tag_snapped: np.ndarray
    tag_moved: np.ndarray
    n_outside: int
    n_snapped: int
    n_moved: int
    n_inserted: int


def merge_time_tags(
    t: np.ndarray, tags: Sequence[float] | np.ndarray, tol: float, *, no_insert: Collection[int] = ()
) -> MergedGrid:
    """Merge a base grid ``t`` (n,) [s], strictly increasing, n ≥ 2, with measurement time tags
    ``tags`` (m,) [s] (any order; processed in the order given).

    ``tol`` [s] ≥ 0: a tag within ``tol`` of its nearest base time is applied at that base step;
    within ``tol`` of a node already inserted in the same interval (by an earlier tag) it shares
    that node.  ``no_insert``: base interval indices i (between ``t[i]`` and ``t[i+1]``) in which no
    node may be inserted; a tag there is applied at the nearer end.  Returns :class:`MergedGrid`
    (module docstring).  Raises ``ValueError`` if ``t`` is not strictly increasing with n ≥ 2.
    """
    t = np.asarray(t, dtype=float)
    n = t.size
    if n < 2 or np.any(np.diff(t) <= 0.0):
        raise ValueError("merge_time_tags: need >= 2 strictly increasing base times")
    tags = np.asarray(tags, dtype=float).reshape(-1)
    m = tags.size
    no_ins = set(int(i) for i in no_insert)
    tag_base = np.full(m, -1, dtype=int)  # base step of a snapped/moved tag
    tag_ins: list[tuple[int, float] | None] = [None] * m  # (interval, node time) of an inserted tag
    snapped = np.zeros(m, dtype=bool)
    moved = np.zeros(m, dtype=bool)
    inserted: dict[int, list[float]] = {}
    n_outside = 0
    for j, tj in enumerate(tags.tolist()):
        if tj < t[0] - tol or tj > t[-1] + tol:
            n_outside += 1
            continue
        k = int(np.clip(np.searchsorted(t, tj), 1, n - 1))
        k = k if abs(t[k] - tj) <= abs(t[k - 1] - tj) else k - 1
        if abs(t[k] - tj) <= tol:
            tag_base[j] = k
            snapped[j] = True
            continue
        i = int(np.searchsorted(t, tj)) - 1
        if i in no_ins:
            tag_base[j] = k
            moved[j] = True
            continue
        lst = inserted.setdefault(i, [])
        tt = next((x for x in lst if abs(x - tj) <= tol), None)
        if tt is None:
            lst.append(tj)
            tt = tj
        tag_ins[j] = (i, tt)
    t_m: list[float] = []
    interval: list[int] = []
    base_node: list[int] = []
    fraction: list[float] = []
    base_to_node = np.empty(n, dtype=int)
    ins_to_node: dict[tuple[int, float], int] = {}
    for k in range(n):
        base_to_node[k] = len(t_m)
        t_m.append(float(t[k]))
        interval.append(k)
        base_node.append(k)
        fraction.append(0.0)
        for tt in sorted(inserted.get(k, ())):
            ins_to_node[(k, tt)] = len(t_m)
            t_m.append(tt)
            interval.append(k)
            base_node.append(-1)
            fraction.append((tt - t[k]) / (t[k + 1] - t[k]))
    tag_node = np.full(m, -1, dtype=int)
    for j in range(m):
        if tag_base[j] >= 0:
            tag_node[j] = base_to_node[tag_base[j]]
        elif tag_ins[j] is not None:
            tag_node[j] = ins_to_node[tag_ins[j]]
    return MergedGrid(
        t=np.array(t_m),
        interval=np.array(interval, dtype=int),
        base_node=np.array(base_node, dtype=int),
        fraction=np.array(fraction),
        tag_node=tag_node,
        tag_snapped=snapped,
        tag_moved=moved,
        n_outside=n_outside,
        n_snapped=int(snapped.sum()),
        n_moved=int(moved.sum()),
        n_inserted=len(ins_to_node),
    )
