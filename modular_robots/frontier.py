"""A pass over the whole space: the compositions of smallest catalogue bound, for the search's frontier.

The best-first search (:mod:`~modular_robots.search`) orders compositions by their key
``(bound, index)``: :func:`~modular_robots.bounds.catalog_bound` and the position in step A's
order (:func:`~modular_robots.composition.enumerate_compositions`). A pass keeps the ``keep``
smallest keys above the last pass's largest, and counts the rest. The bounds come in chunks
(:func:`bound_chunks`): a block of a general catalogue's assemblies at once where
:func:`~modular_robots.bounds.block_bounds` applies (the same values to the last bit), one
composition at a time otherwise. Only the kept compositions are built.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .assembly import AssemblyBlock, assembly_blocks
from .bounds import block_bounds, catalog_bound
from .catalog import Catalog
from .composition import Composition, enumerate_compositions
from .scenario import Task

__all__ = ["BoundChunk", "FrontierPass", "bound_chunks", "take_pass", "BLOCK_LIMIT", "CHUNK"]

#: A block of more assemblies than this is bounded a run of its first gap at a time.
BLOCK_LIMIT = 1 << 20
#: Compositions bounded one at a time are taken in chunks of this many.
CHUNK = 4096


@dataclass(frozen=True)
class BoundChunk:
    """The catalogue bounds ``values`` of the compositions ``start``, ``start + 1``, ... of step
    A's order, and how to build the composition at a position of the chunk: at once when
    ``eager`` (the chunk holds its compositions, which are let go after it), else when needed (a
    block builds any of its assemblies)."""

    start: int
    values: np.ndarray
    build: Callable[[int], Composition]
    eager: bool = False


@dataclass(frozen=True)
class FrontierPass:
    """What a pass keeps, ``kept`` as ``(bound, index, composition)`` in ascending key order, and
    what it leaves: ``beyond`` compositions above the last pass's key that it did not keep, the
    smallest of their bounds ``smallest``, and ``bounded``, the compositions it bounded.
    ``complete`` is False when a deadline ended it before the end of the space."""

    kept: list[tuple[float, int, Composition]]
    beyond: int
    smallest: float
    bounded: int
    complete: bool


def bound_chunks(catalog: Catalog, task: Task, tolerance: float) -> Iterator[BoundChunk]:
    """The catalogue bounds of every composition, in step A's order, chunk by chunk."""
    start = 0
    if catalog.general:
        for whole in assembly_blocks(catalog):
            for block in _split(whole):
                values = block_bounds(block, catalog, task, tolerance)
                if values is not None:
                    yield BoundChunk(start, values, _builder(block))
                    start += len(values)
                    continue
                compositions = (Composition(ids, block.dof) for ids in block.assemblies())
                for chunk in _one_by_one(compositions, catalog, task, tolerance, start):
                    yield chunk
                    start += len(chunk.values)
        return
    yield from _one_by_one(enumerate_compositions(catalog), catalog, task, tolerance, 0)


def _split(block: AssemblyBlock) -> Iterator[AssemblyBlock]:
    """``block`` in order, as blocks of at most :data:`BLOCK_LIMIT` assemblies where it can be
    split: a run at a time of its first gap of several runs, recursively."""
    shape = block.shape
    if shape is None or math.prod(shape) <= BLOCK_LIMIT:
        yield block
        return
    at = next(g for g, size in enumerate(shape) if size > 1)
    gaps = block.gaps
    for run in gaps[at]:
        part = (*gaps[:at], (run,), *gaps[at + 1 :])
        yield from _split(AssemblyBlock(block.base, block.joints, block.effector, part, block.dof))


def _builder(block: AssemblyBlock) -> Callable[[int], Composition]:
    shape = block.shape
    assert shape is not None

    def build(position: int) -> Composition:
        choice = np.unravel_index(position, shape)
        return Composition(block.at([int(i) for i in choice]), block.dof)

    return build


def _one_by_one(
    compositions: Iterator[Composition], catalog: Catalog, task: Task, tolerance: float, start: int
) -> Iterator[BoundChunk]:
    while chunk := list(itertools.islice(compositions, CHUNK)):
        values = np.array([catalog_bound(c, catalog, task, tolerance).value for c in chunk])
        yield BoundChunk(start, values, chunk.__getitem__, eager=True)
        start += len(chunk)


def take_pass(
    chunks: Iterator[BoundChunk],
    keep: int,
    after: tuple[float, float] | None,
    stop: Callable[[], bool] | None = None,
    progress: Callable[[int], None] | None = None,
) -> FrontierPass:
    """The ``keep`` compositions of smallest key above ``after`` (every one when ``after`` is
    None) among ``chunks``, and a count of the others above it. When ``stop()`` (asked before
    every chunk) is true, the pass ends where it is; ``progress(bounded)`` is called after every
    chunk."""
    held: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (values, indices, chunk numbers)
    builders: dict[int, tuple[int, Callable[[int], Composition]]] = {}  # (start, build) of lazy chunks held from
    built: dict[int, Composition] = {}  # held compositions of eager chunks, by index
    held_count = 0
    limit: tuple[float, float] = (math.inf, math.inf)  # the largest key held, once ``keep`` are
    above = bounded = 0
    smallest = math.inf
    complete = True

    def compact() -> None:
        nonlocal held, held_count, limit, smallest
        values, indices, numbers = (np.concatenate(parts) for parts in zip(*held, strict=True))
        order = np.lexsort((indices, values))
        if len(order) > keep:
            smallest = min(smallest, float(values[order[keep:]].min()))
            order = order[:keep]
        held = [(values[order], indices[order], numbers[order])]
        held_count = len(order)
        if held_count == keep and keep:
            limit = (float(values[order[-1]]), float(indices[order[-1]]))
        for number in set(builders) - set(numbers[order].tolist()):
            del builders[number]
        for index in set(built) - set(indices[order].tolist()):
            del built[index]

    for number, chunk in enumerate(chunks):
        if stop is not None and stop():
            complete = False
            break
        values = chunk.values
        indices = chunk.start + np.arange(len(values))
        bounded += len(values)
        wanted = np.ones(len(values), dtype=bool) if after is None else _above(values, indices, after)
        above += int(wanted.sum())
        within = wanted & _below(values, indices, limit)
        out = wanted & ~within
        if out.any():
            smallest = min(smallest, float(values[out].min()))
        count = int(within.sum())
        if count:
            held.append((values[within], indices[within], np.full(count, number)))
            if chunk.eager:
                built.update((int(i), chunk.build(int(i) - chunk.start)) for i in indices[within])
            else:  # not the chunk itself: its values would be held with it
                builders[number] = (chunk.start, chunk.build)
            held_count += count
            if held_count >= 2 * keep:
                compact()
        if progress is not None:
            progress(bounded)
    if held:
        compact()
    kept: list[tuple[float, int, Composition]] = []
    if held:
        values, indices, numbers = held[0]
        for value, index, number in zip(values.tolist(), indices.tolist(), numbers.tolist(), strict=True):
            composition = built.get(index)
            if composition is None:
                start, build = builders[number]
                composition = build(index - start)
            kept.append((value, index, composition))
    return FrontierPass(kept, above - len(kept), smallest, bounded, complete)


def _above(values: np.ndarray, indices: np.ndarray, key: tuple[float, float]) -> np.ndarray:
    """Whether each key ``(values[i], indices[i])`` is above ``key`` (lexicographically)."""
    return (values > key[0]) | ((values == key[0]) & (indices > key[1]))


def _below(values: np.ndarray, indices: np.ndarray, key: tuple[float, float]) -> np.ndarray:
    """Whether each key ``(values[i], indices[i])`` is below ``key``."""
    return (values < key[0]) | ((values == key[0]) & (indices < key[1]))
