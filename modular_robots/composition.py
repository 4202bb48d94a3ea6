"""Step A: compositions of catalogue modules, enumerated from the catalogue's grammar.

The grammar is data (:class:`~modular_robots.catalog.Grammar`)::

    base  link{links_after_base}  (joint link{links_after_joint})*  effector

with the total DOF in ``grammar.dof``. Enumeration is a generator: each composition once, in a
deterministic order (DOF ascending, then base, effector and the
chain in catalogue order), in bounded memory.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache
from typing import cast

from .assembly import assembly_error, enumerate_assemblies
from .catalog import Catalog, Grammar, Module
from .exceptions import CatalogError, CompositionError, shorten
from .modules import AssemblyGrammar, Connector, GeneralModule

__all__ = ["Composition", "enumerate_compositions", "count_compositions", "MAX_RUN_TRIALS"]

SEPARATOR = "-"
#: The most link runs the listing of a general catalogue may try: it builds each run the grammar's
#: ranges or whitelists allow (every sequence of link modules, compatible or not) and keeps those
#: whose connectors meet, about a million a second. Beyond (10 s), listing is refused before any work.
MAX_RUN_TRIALS = 10_000_000
#: Link runs built and checked per second by the listing (measured: 1.2 million on 2 shared cores).
RUN_TRIALS_PER_SECOND = 1e6


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


def _link_runs(links: tuple[Module, ...], bounds: tuple[int, int]) -> list[tuple[str, ...]]:
    ids = [m.id for m in links]
    return [run for k in range(bounds[0], bounds[1] + 1) for run in itertools.product(ids, repeat=k)]


def enumerate_compositions(catalog: Catalog, dof: int | None = None) -> Iterator[Composition]:
    """Yield every composition the grammar allows, once each, DOF ascending.

    Parameters
    ----------
    catalog
        The module catalogue and its grammar.
    dof
        Only compositions with exactly this many DOF (default: the grammar's whole range).

    Raises
    ------
    CompositionError
        At the call, before any work: for a DOF out of the grammar's range, and for a general
        catalogue whose link runs are too many to try (more than :data:`MAX_RUN_TRIALS`), with
        the estimate.
    """
    wanted = _dof_range(catalog, dof)
    if catalog.general:
        return _general_listing(catalog, dof, wanted)
    return _convention_a_compositions(catalog, wanted)


def _general_compositions(catalog: Catalog, dof: int | None) -> Iterator[Composition]:
    for ids in enumerate_assemblies(catalog, dof):
        yield Composition(ids, sum(catalog.general_module(i).dof for i in ids))


def _convention_a_compositions(catalog: Catalog, wanted: range) -> Iterator[Composition]:
    g = catalog.grammar
    assert isinstance(g, Grammar), "a convention-A catalogue's grammar"
    joints = catalog.of_kind("joint")
    blocks = [(j.id, *run) for j in joints for run in _link_runs(catalog.of_kind("link"), g.links_after_joint)]
    base_runs = _link_runs(catalog.of_kind("link"), g.links_after_base)
    for total in wanted:
        for base in catalog.of_kind("base"):
            for pre in base_runs:
                for effector in catalog.of_kind("effector"):
                    n_joints = total - base.dof - effector.dof
                    if n_joints < 0:
                        continue
                    for chain in itertools.product(blocks, repeat=n_joints):
                        ids = (base.id, *pre, *itertools.chain.from_iterable(chain), effector.id)
                        yield Composition(ids, total)


def count_compositions(catalog: Catalog, dof: int | None = None) -> dict[int, int]:
    """Number of compositions per DOF (only ``dof`` if given), in closed form: nothing is
    enumerated (general catalogues: by dynamic programming over connector kinds, see
    :class:`_GeneralCount`; DOFs no assembly has are left out unless ``dof`` asks for one)."""
    if catalog.general:
        counts = _GeneralCount(catalog).per_dof(_dof_range(catalog, dof))
        return {d: n for d, n in counts.items() if n or dof is not None}
    g = catalog.grammar
    assert isinstance(g, Grammar), "a convention-A catalogue's grammar"
    n_links = len(catalog.of_kind("link"))
    per_run = sum(n_links**k for k in range(g.links_after_joint[0], g.links_after_joint[1] + 1))
    per_base = sum(n_links**k for k in range(g.links_after_base[0], g.links_after_base[1] + 1))
    per_block = len(catalog.of_kind("joint")) * per_run
    counts = {}
    for total in _dof_range(catalog, dof):
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


# -- general catalogues: counting by dynamic programming over connector kinds ------------------------
#: A connector as compatibility sees it: gender, type and size (:meth:`Connector.meets`).
ConnectorKind = tuple[str, str, tuple[float, ...]]


def _kind(connector: Connector) -> ConnectorKind:
    return (connector.gender, connector.type, connector.size)


def _meets(a: ConnectorKind, b: ConnectorKind) -> bool:
    return {a[0], b[0]} == {"m", "f"} and a[1:] == b[1:]


class _GeneralCount:
    """The assemblies of a general catalogue (:mod:`~modular_robots.assembly`'s grammar) counted
    without listing any: modules are grouped by what compatibility and the grammar see of them
    (their connectors' kinds, their DOF, the whitelist slots that name them), so the work grows
    with the number of distinct groups, not with modules, runs or assemblies.

    A link run is counted by a walk over the run's grammar as an automaton: the slots of a
    whitelist (``between_joints``, ``before_end``) or ``low`` required and ``high - low`` optional
    slots open to every link (the length ranges); its state is the set of slots the run may have
    filled (so a run that two slot choices give counts once, as the listing lists it once) and
    the kind of the last output connector."""

    def __init__(self, catalog: Catalog):
        grammar = catalog.grammar
        assert isinstance(grammar, AssemblyGrammar), "a general catalogue's grammar"
        self.grammar = grammar
        self.modules = cast("tuple[GeneralModule, ...]", catalog.modules)
        self.by_id = {m.id: m for m in self.modules}
        self.links = [m for m in self.modules if m.kind == "link"]
        self.bases = Counter(_kind(m.outlet) for m in self.modules if m.kind == "base")
        self.effectors = Counter(_kind(m.inlet) for m in self.modules if m.kind == "effector")
        self.joints = Counter((_kind(m.inlet), _kind(m.outlet), m.dof) for m in self.modules if m.kind == "joint")
        self.runs = cache(self._runs)
        self._automata: dict[
            str, tuple[tuple[bool, ...], list[tuple[ConnectorKind, ConnectorKind, frozenset[int], int]]]
        ] = {}

    def _automaton(
        self, where: str
    ) -> tuple[tuple[bool, ...], list[tuple[ConnectorKind, ConnectorKind, frozenset[int], int]]]:
        """The slots' optional flags and the link groups (input kind, output kind, the slots that
        take them, how many links) of the runs at ``where`` (``start``, ``between``, ``end``)."""
        if where not in self._automata:
            g = self.grammar
            pattern = {"between": g.between_joints, "end": g.before_end}.get(where)
            if pattern is not None:
                optional = tuple(flag for _, flag in pattern.slots)
                members = {
                    m.id: frozenset(i for i, (ids, _) in enumerate(pattern.slots) if m.id in ids) for m in self.links
                }
            else:
                low, high = {"between": g.links_between_joints, "start": g.links_before_first_joint}.get(
                    where, g.links_after_last_joint
                )
                optional = tuple(i >= low for i in range(high))
                members = {m.id: frozenset(range(high)) for m in self.links}
            groups = Counter((_kind(m.inlet), _kind(m.outlet), members[m.id]) for m in self.links if members[m.id])
            self._automata[where] = (optional, [(a, b, slots, n) for (a, b, slots), n in groups.items()])
        return self._automata[where]

    def _runs(self, where: str, before: ConnectorKind, after: ConnectorKind) -> int:
        """The number of link runs allowed at ``where`` between an output of kind ``before`` and
        an input of kind ``after``."""
        optional, groups = self._automaton(where)
        end = len(optional)

        def closure(slots: frozenset[int]) -> frozenset[int]:
            out = set(slots)
            for i in range(end):  # ascending: a skipped optional slot may open the next one
                if i in out and optional[i]:
                    out.add(i + 1)
            return frozenset(out)

        layer: dict[tuple[frozenset[int], ConnectorKind], int] = {(closure(frozenset({0})), before): 1}
        total = 0
        while layer:  # each step fills a slot: at most ``end`` steps
            nxt: Counter[tuple[frozenset[int], ConnectorKind]] = Counter()
            for (slots, kind), n in layer.items():
                if end in slots and _meets(kind, after):
                    total += n
                for inlet, outlet, takes, size in groups:
                    if _meets(kind, inlet):
                        filled = closure(frozenset(i + 1 for i in slots if i in takes))
                        if filled:
                            nxt[(filled, outlet)] += n * size
            layer = nxt
        return total

    def _ends(self, kind: ConnectorKind) -> int:
        """Ways to finish from an output of ``kind``: a run before the end, then an effector."""
        return sum(n * self.runs("end", kind, e) for e, n in self.effectors.items())

    def per_dof(self, wanted: range) -> dict[int, int]:
        counts = dict.fromkeys(wanted, 0)
        g = self.grammar
        if 0 in counts and (g.joint_sequences is None or () in g.joint_sequences):
            counts[0] += sum(n * self._ends(b) for b, n in self.bases.items())  # base, one run, effector
        if g.joint_sequences is not None:
            for seq in g.joint_sequences:
                d = sum(self.by_id[j].dof for j in seq)
                if not seq or d not in counts:
                    continue
                modules = [self.by_id[j] for j in seq]
                ways = sum(n * self.runs("start", b, _kind(modules[0].inlet)) for b, n in self.bases.items())
                for a, b in itertools.pairwise(modules):
                    ways *= self.runs("between", _kind(a.outlet), _kind(b.inlet))
                counts[d] += ways * self._ends(_kind(modules[-1].outlet))
            return counts
        max_dof = max(wanted, default=-1)
        # layer[(output kind, dof)]: ways to have placed joint modules ending in that output, with that DOF
        layer: Counter[tuple[ConnectorKind, int]] = Counter()
        for (inlet, outlet, dof), m in self.joints.items():
            if dof <= max_dof:
                layer[(outlet, dof)] += m * sum(n * self.runs("start", b, inlet) for b, n in self.bases.items())
        while layer:  # each step adds a joint module (>= 1 DOF): at most max_dof steps
            nxt: Counter[tuple[ConnectorKind, int]] = Counter()
            for (kind, d), n in layer.items():
                if not n:
                    continue
                if d in counts:
                    counts[d] += n * self._ends(kind)
                for (inlet, outlet, dof), m in self.joints.items():
                    if d + dof <= max_dof:
                        nxt[(outlet, d + dof)] += n * m * self.runs("between", kind, inlet)
            layer = nxt
        return counts


def _run_trials(catalog: Catalog, wanted: range) -> int:
    """How many link runs :func:`~modular_robots.assembly.enumerate_assemblies` would build (at
    most): per pair of neighbours it may join by a run, every run of the grammar's ranges or
    whitelists, compatible or not."""
    g = catalog.grammar
    assert isinstance(g, AssemblyGrammar), "a general catalogue's grammar"
    modules = cast("tuple[GeneralModule, ...]", catalog.modules)
    by_id = {m.id: m for m in modules}
    n = Counter(m.kind for m in modules)
    n_links = n["link"]

    def per_run(where: str) -> int:
        pattern = {"between": g.between_joints, "end": g.before_end}.get(where)
        if pattern is not None:
            return math.prod(len(ids) + optional for ids, optional in pattern.slots)
        low, high = {"between": g.links_between_joints, "start": g.links_before_first_joint}.get(
            where, g.links_after_last_joint
        )
        return sum(n_links**k for k in range(low, high + 1))

    trials = 0
    if 0 in wanted:
        trials += n["base"] * n["effector"] * per_run("end")
    if g.joint_sequences is not None:
        seqs = [s for s in g.joint_sequences if s and sum(by_id[j].dof for j in s) in wanted]
        firsts, lasts = {s[0] for s in seqs}, {s[-1] for s in seqs}
        pairs = {p for s in seqs for p in itertools.pairwise(s)}
        trials += n["base"] * len(firsts) * per_run("start") + len(pairs) * per_run("between")
        trials += len(lasts) * n["effector"] * per_run("end")
    elif n["joint"] and max(wanted, default=0) > 0:
        trials += n["base"] * n["joint"] * per_run("start") + n["joint"] * n["effector"] * per_run("end")
        least = min(m.dof for m in modules if m.kind == "joint")
        if max(wanted) >= 2 * least:  # room for two joint modules: runs between them
            trials += n["joint"] ** 2 * per_run("between")
    return trials


def _general_listing(catalog: Catalog, dof: int | None, wanted: range) -> Iterator[Composition]:
    """The general catalogue's compositions, refused before any work if listing them would try
    more than :data:`MAX_RUN_TRIALS` link runs."""
    trials = _run_trials(catalog, wanted)
    if trials <= MAX_RUN_TRIALS:
        return _general_compositions(catalog, dof)
    total = sum(_GeneralCount(catalog).per_dof(wanted).values())
    if total == 0:
        return iter(())
    raise CompositionError(
        f"the catalogue {shorten(catalog.name)} ({len(catalog.modules)} modules) is too large to list: listing its "
        f"{total:,} compositions would try up to {trials:,} link runs (the limit is {MAX_RUN_TRIALS:,}; about "
        f"{_duration(trials / RUN_TRIALS_PER_SECOND)}). Count them (enumerate --count), or narrow the grammar: "
        "shorter link runs (links_between_joints, links_before_first_joint, links_after_last_joint), joint_sequences "
        "or whitelists (between_joints, before_end)"
    )


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("hours", 3600.0), ("minutes", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:,.3g} {unit}"
    return f"{seconds:.3g} s"
