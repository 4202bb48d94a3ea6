"""Step A: compositions of catalogue modules, enumerated from the catalogue's grammar.

The grammar is data (:class:`~modular_robots.catalog.Grammar`)::

    base  link{links_after_base}  (joint link{links_after_joint})*  effector

with the total DOF in ``grammar.dof``; a general catalogue's is
:class:`~modular_robots.modules.AssemblyGrammar` (:mod:`~modular_robots.assembly`). Counting
never lists (closed form, or dynamic programming over a general grammar). Enumeration is a
generator: each composition once, in a deterministic order (DOF ascending, then base, effector
and the chain in catalogue order), each after a bounded amount of work and in bounded memory, so
the first of a space of any size comes at once and a prefix (``filter --limit``) costs its own
length.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from .assembly import assembly_blocks, assembly_error, count_assemblies, pool, product
from .catalog import Catalog, Grammar, Module
from .exceptions import CatalogError, CompositionError, shorten

__all__ = ["Composition", "enumerate_compositions", "count_compositions"]

SEPARATOR = "-"


@dataclass(frozen=True, order=True)
class Composition:
    """A serial chain of module ids, base first, effector last, e.g. ``B-J1-L2-E1``."""

    modules: tuple[str, ...]
    dof: int

    @property
    def name(self) -> str:
        return SEPARATOR.join(self.modules)

    def __str__(self) -> str:
        return self.name

    @classmethod
    def from_name(cls, name: str, catalog: Catalog) -> Composition:
        """Parse ``name`` (ids joined by ``-``) and check it against the catalogue's grammar.

        Raises
        ------
        CompositionError
            For an unknown module or a sequence the grammar does not allow, saying which.
        """
        ids = tuple(part.strip() for part in str(name).split(SEPARATOR))
        if not name or any(not part for part in ids):
            raise CompositionError(f"composition {shorten(name)}: expected module ids joined by '-', e.g. B-J1-L2-E1")
        modules = []
        for position, module_id in enumerate(ids):
            try:
                modules.append(catalog.module(module_id))
            except CatalogError as exc:
                raise CompositionError(f"composition {shorten(name)}, position {position + 1}: {exc}") from None
        if catalog.general:
            problem = assembly_error(catalog, ids)
            if problem:
                raise CompositionError(f"composition {shorten(name)}: {problem} (catalogue {shorten(catalog.name)})")
        else:
            _check_grammar(name, modules, catalog)
        return cls(ids, sum(m.dof for m in modules))


def _check_grammar(name: str, modules: list[Module], catalog: Catalog) -> None:
    g = catalog.grammar
    assert isinstance(g, Grammar), "a convention-A catalogue's grammar"

    def fail(message: str) -> CompositionError:
        return CompositionError(f"composition {shorten(name)}: {message} (catalogue {shorten(catalog.name)})")

    if modules[0].kind != "base":
        raise fail(f"must start with a base module, not {modules[0].id} ({modules[0].kind})")
    if len(modules) < 2 or modules[-1].kind != "effector":
        raise fail(f"must end with an effector module, not {modules[-1].id} ({modules[-1].kind})")
    run, after = 0, "base"
    for position, module in enumerate(modules[1:-1], start=2):
        if module.kind == "link":
            run += 1
            continue
        if module.kind != "joint":
            raise fail(f"position {position}: {module.id} ({module.kind}) may only be first or last")
        _check_run(fail, run, after, g)
        run, after = 0, "joint"
    _check_run(fail, run, after, g)
    dof = sum(m.dof for m in modules)
    if not g.dof[0] <= dof <= g.dof[1]:
        raise fail(f"has {dof} DOF; the grammar allows {g.dof[0]} to {g.dof[1]}")


def _check_run(fail: Callable[[str], CompositionError], run: int, after: str, g: Grammar) -> None:
    low, high = g.links_after_joint if after == "joint" else g.links_after_base
    if not low <= run <= high:
        raise fail(f"{run} link(s) after a {after}; the grammar allows {low} to {high}")


def _link_runs(links: tuple[str, ...], bounds: tuple[int, int]) -> Iterator[tuple[str, ...]]:
    for k in range(bounds[0], bounds[1] + 1):
        yield from itertools.product(links, repeat=k)


def _runs_count(n_links: int, bounds: tuple[int, int]) -> int:
    return sum(n_links**k for k in range(bounds[0], bounds[1] + 1))


def enumerate_compositions(catalog: Catalog, dof: int | None = None) -> Iterator[Composition]:
    """Yield every composition the grammar allows, once each, DOF ascending, each after a bounded
    amount of work and in bounded memory (the caller bounds the space: :func:`count_compositions`).

    Parameters
    ----------
    catalog
        The module catalogue and its grammar.
    dof
        Only compositions with exactly this many DOF (default: the grammar's whole range).

    Raises
    ------
    CompositionError
        At the call, before any work: for a DOF out of the grammar's range.
    """
    wanted = _dof_range(catalog, dof)
    if catalog.general:
        return _general_compositions(catalog, dof)
    return _convention_a_compositions(catalog, wanted)


def _general_compositions(catalog: Catalog, dof: int | None) -> Iterator[Composition]:
    for block in assembly_blocks(catalog, dof):
        for ids in block.assemblies():
            yield Composition(ids, block.dof)


def _convention_a_compositions(catalog: Catalog, wanted: range) -> Iterator[Composition]:
    """Convention A's compositions; a set of link runs or joint blocks too large to hold
    (:data:`~modular_robots.assembly.KEEP_RUNS`) is listed again at each walk."""
    g = catalog.grammar
    assert isinstance(g, Grammar), "a convention-A catalogue's grammar"
    joints = tuple(m.id for m in catalog.of_kind("joint"))
    links = tuple(m.id for m in catalog.of_kind("link"))
    blocks = pool(
        lambda: ((j, *run) for j in joints for run in _link_runs(links, g.links_after_joint)),
        len(joints) * _runs_count(len(links), g.links_after_joint),
    )
    base_runs = pool(lambda: _link_runs(links, g.links_after_base), _runs_count(len(links), g.links_after_base))
    for total in wanted:
        for base in catalog.of_kind("base"):
            for pre in base_runs:
                for effector in catalog.of_kind("effector"):
                    n_joints = total - base.dof - effector.dof
                    if n_joints < 0:
                        continue
                    for chain in product([blocks] * n_joints):
                        ids = (base.id, *pre, *itertools.chain.from_iterable(chain), effector.id)
                        yield Composition(ids, total)


def count_compositions(catalog: Catalog, dof: int | None = None) -> dict[int, int]:
    """Number of compositions per DOF (only ``dof`` if given), nothing enumerated: in closed form,
    or for a general catalogue by dynamic programming over its grammar
    (:func:`~modular_robots.assembly.count_assemblies`; DOFs no assembly has are left out unless
    ``dof`` asks for one)."""
    wanted = _dof_range(catalog, dof)
    if catalog.general:
        return count_assemblies(catalog, dof)
    g = catalog.grammar
    assert isinstance(g, Grammar), "a convention-A catalogue's grammar"
    n_links = len(catalog.of_kind("link"))
    per_base = _runs_count(n_links, g.links_after_base)
    per_block = len(catalog.of_kind("joint")) * _runs_count(n_links, g.links_after_joint)
    counts = {}
    for total in wanted:
        counts[total] = sum(
            per_base * per_block ** (total - b.dof - e.dof)
            for b in catalog.of_kind("base")
            for e in catalog.of_kind("effector")
            if total - b.dof - e.dof >= 0
        )
    return counts


def _dof_range(catalog: Catalog, dof: int | None) -> range:
    low, high = catalog.grammar.dof
    if dof is None:
        return range(low, high + 1)
    if not low <= dof <= high:
        raise CompositionError(f"--dof {dof}: the catalogue {shorten(catalog.name)} allows {low} to {high} DOF")
    return range(dof, dof + 1)
