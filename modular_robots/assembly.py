"""Step A for general catalogues: serial assemblies by connector compatibility.

An assembly is ``base, run, J, run, J, ..., J, run, effector``: joint modules ``J`` (their joints
summed in ``dof``), link runs between them, a run after the base and one before the effector,
each neighbour pair meeting (a male output on a female input of the same type and size). The
runs' lengths follow the grammar's ranges, or its whitelists (Timor's ``Science2019`` iterator
and its test of the Science Robotics 2019 space; see
:class:`~modular_robots.modules.AssemblyGrammar`).

Compatibility sees a connector's gender, type and size only (its *kind*), so everything here works
on kinds: the work grows with the distinct kinds and the grammar's lengths, not with the number of
modules, runs or assemblies. Counting is dynamic programming over the grammar; nothing is listed.
Listing is a generator that extends only partial assemblies the counts say can be completed, so
each assembly comes after a bounded amount of work (the first at once) in bounded memory, however
large the space: DOF ascending, then base, effector, joint modules and the runs, each in catalogue
order (a whitelist's ids in the slot's order).
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from typing import cast

from .catalog import Catalog
from .modules import AssemblyGrammar, Connector, GeneralModule, RunPattern

__all__ = [
    "AssemblyBlock",
    "assembly_blocks",
    "count_assemblies",
    "enumerate_assemblies",
    "assembly_error",
    "KEEP_RUNS",
    "pool",
    "product",
]

Ids = tuple[str, ...]
#: A connector as compatibility sees it: gender, type and size (:meth:`Connector.meets`).
Kind = tuple[str, str, tuple[float, ...]]
#: A whitelist's choice per slot: a module id, or None for an optional slot left empty.
Choice = tuple[str | None, ...]

#: A set of runs (or convention A's blocks) is kept in memory when it has at most this many
#: members, for ``itertools.product``'s speed; a larger one is listed afresh each time it is walked.
KEEP_RUNS = 4096


class _Again:
    """An iterable listed afresh by ``factory`` at each walk: a large set in no memory."""

    def __init__(self, factory: Callable[[], Iterator[Ids]]):
        self.factory = factory

    def __iter__(self) -> Iterator[Ids]:
        return self.factory()


def pool(factory: Callable[[], Iterator[Ids]], size: int) -> Iterable[Ids]:
    """The ``size`` items ``factory`` lists, held as a tuple if few (:data:`KEEP_RUNS`), else
    listed again at each walk."""
    return tuple(factory()) if size <= KEEP_RUNS else _Again(factory)


def product(pools: Sequence[Iterable[Ids]]) -> Iterator[tuple[Ids, ...]]:
    """``itertools.product(*pools)`` (the first pool slowest), without holding a pool that is not
    a tuple: ``itertools.product`` would first copy every pool into memory."""
    if all(isinstance(p, tuple) for p in pools):
        yield from itertools.product(*pools)
        return

    def walk(i: int, done: tuple[Ids, ...]) -> Iterator[tuple[Ids, ...]]:
        if i == len(pools):
            yield done
            return
        for item in pools[i]:
            yield from walk(i + 1, (*done, item))

    yield from walk(0, ())


@dataclass(frozen=True, eq=False)
class AssemblyBlock:
    """The assemblies of one ``base``, sequence of joint modules and ``effector``: one link run
    from each of ``gaps`` (after the base, between consecutive joint modules, before the
    effector), listed as :func:`product` walks them, the last gap fastest. Every one has ``dof``
    joints (the base's and the effector's included)."""

    base: str
    joints: Ids
    effector: str
    gaps: tuple[Iterable[Ids], ...]
    dof: int

    @property
    def shape(self) -> tuple[int, ...] | None:
        """The number of runs in each gap, when every gap is held in memory (None otherwise)."""
        if not all(isinstance(gap, tuple) for gap in self.gaps):
            return None
        return tuple(len(cast("tuple[Ids, ...]", gap)) for gap in self.gaps)

    @property
    def size(self) -> int | None:
        """The number of assemblies, when :attr:`shape` is known."""
        shape = self.shape
        return None if shape is None else math.prod(shape)

    def assembly(self, runs: Sequence[Ids]) -> Ids:
        """The module ids of the assembly with one run per gap."""
        ids = [self.base, *runs[0]]
        for joint, run in zip(self.joints, runs[1:], strict=True):
            ids += [joint, *run]
        return (*ids, self.effector)

    def assemblies(self) -> Iterator[Ids]:
        """Every assembly of the block, in order."""
        for runs in product(self.gaps):
            yield self.assembly(runs)

    def at(self, choice: Sequence[int]) -> Ids:
        """The assembly of run ``choice[g]`` of each gap ``g`` (gaps held in memory)."""
        gaps = cast("tuple[tuple[Ids, ...], ...]", self.gaps)
        return self.assembly([gap[i] for gap, i in zip(gaps, choice, strict=True)])


def _kind(connector: Connector) -> Kind:
    return (connector.gender, connector.type, connector.size)


def _meets(a: Kind, b: Kind) -> bool:
    return {a[0], b[0]} == {"m", "f"} and a[1:] == b[1:]


class _Space:
    """A catalogue's modules by kind and connector kinds, and the grammar's link runs, counted
    and listed between connector kinds (``where``: ``start`` after the base, ``between`` two
    joint modules, ``end`` before the effector)."""

    def __init__(self, catalog: Catalog):
        grammar = catalog.grammar
        assert isinstance(grammar, AssemblyGrammar), "a general catalogue's grammar"
        self.grammar: AssemblyGrammar = grammar
        # A general catalogue's modules (its grammar is an AssemblyGrammar) are GeneralModules.
        modules = cast("tuple[GeneralModule, ...]", catalog.modules)
        self.by_id: dict[str, GeneralModule] = {m.id: m for m in modules}
        self.inlet = {m.id: _kind(m.inlet) for m in modules}
        self.outlet = {m.id: _kind(m.outlet) for m in modules}
        kinds: dict[str, list[str]] = {"base": [], "joint": [], "link": [], "effector": []}
        for m in modules:
            kinds[m.kind].append(m.id)
        self.bases, self.joints, self.links, self.effectors = (
            tuple(kinds[k]) for k in ("base", "joint", "link", "effector")
        )
        self.joint_kinds = tuple(dict.fromkeys((self.inlet[j], self.outlet[j], self.dof(j)) for j in self.joints))
        self.count_runs = cache(self._count_runs)
        self.runs = cache(self._runs)
        self.finishes = cache(self._finishes)
        self._followers = cache(self._followers_of)
        self._reaches = cache(self._reaches_in)
        self._pattern_reaches = cache(self._pattern_reaches_from)
        self._automata: dict[str, tuple[tuple[bool, ...], list[tuple[Kind, Kind, frozenset[int], int]]]] = {}

    def dof(self, module_id: str) -> int:
        return self.by_id[module_id].dof

    def meets(self, a: str, b: str) -> bool:
        return _meets(self.outlet[a], self.inlet[b])

    def pattern(self, where: str) -> RunPattern | None:
        return {"between": self.grammar.between_joints, "end": self.grammar.before_end}.get(where)

    def lengths(self, where: str) -> tuple[int, int]:
        g = self.grammar
        return {"between": g.links_between_joints, "start": g.links_before_first_joint}.get(
            where, g.links_after_last_joint
        )

    # -- counting ----------------------------------------------------------------------------
    def _automaton(self, where: str) -> tuple[tuple[bool, ...], list[tuple[Kind, Kind, frozenset[int], int]]]:
        """The slots' optional flags and the link groups (input kind, output kind, the slots that
        take them, how many links) of the runs at ``where``: a whitelist's slots, or ``low``
        required and ``high - low`` optional slots open to every link (the length ranges)."""
        if where not in self._automata:
            pattern = self.pattern(where)
            if pattern is not None:
                optional = tuple(flag for _, flag in pattern.slots)
                members = {
                    link: frozenset(i for i, (ids, _) in enumerate(pattern.slots) if link in ids) for link in self.links
                }
            else:
                low, high = self.lengths(where)
                optional = tuple(i >= low for i in range(high))
                members = dict.fromkeys(self.links, frozenset(range(high)))
            groups = Counter((self.inlet[k], self.outlet[k], members[k]) for k in self.links if members[k])
            self._automata[where] = (optional, [(a, b, slots, n) for (a, b, slots), n in groups.items()])
        return self._automata[where]

    def _count_runs(self, where: str, before: Kind, after: Kind) -> int:
        """The number of distinct link runs allowed at ``where`` between an output of kind
        ``before`` and an input of kind ``after``: a walk over the slots whose state is the set of
        slots the run may have filled (so a run two slot choices give counts once, as it is
        listed once) and the kind of its last output."""
        optional, groups = self._automaton(where)
        end = len(optional)

        def closure(slots: frozenset[int]) -> frozenset[int]:
            out = set(slots)
            for i in range(end):  # ascending: a skipped optional slot may open the next one
                if i in out and optional[i]:
                    out.add(i + 1)
            return frozenset(out)

        layer: dict[tuple[frozenset[int], Kind], int] = {(closure(frozenset({0})), before): 1}
        total = 0
        while layer:  # each step fills a slot: at most ``end`` steps
            nxt: Counter[tuple[frozenset[int], Kind]] = Counter()
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

    def _finishes(self, kind: Kind, left: int, effector: Kind) -> bool:
        """Whether joint modules of ``left`` joints in all, then a run and an effector of input
        ``effector``, can follow a joint module's output of ``kind``."""
        if left == 0:
            return self.count_runs("end", kind, effector) > 0
        return any(
            dof <= left and self.count_runs("between", kind, inlet) and self.finishes(outlet, left - dof, effector)
            for inlet, outlet, dof in self.joint_kinds
        )

    def ends(self, kind: Kind) -> int:
        """Ways to finish from an output of ``kind``: a run before the end, then an effector."""
        return sum(self.count_runs("end", kind, self.inlet[e]) for e in self.effectors)

    def per_dof(self, wanted: range) -> dict[int, int]:
        """Assemblies per DOF in ``wanted``, by dynamic programming over (output kind, joints so far)."""
        counts = dict.fromkeys(wanted, 0)
        g = self.grammar
        starts = Counter(self.outlet[b] for b in self.bases)
        if 0 in counts and _allows_no_joint(g):
            counts[0] += sum(n * self.ends(b) for b, n in starts.items())  # base, one run, effector
        if g.joint_sequences is not None:
            for seq in g.joint_sequences:
                d = sum(self.dof(j) for j in seq)
                if not seq or d not in counts:
                    continue
                ways = sum(n * self.count_runs("start", b, self.inlet[seq[0]]) for b, n in starts.items())
                for a, b in itertools.pairwise(seq):
                    ways *= self.count_runs("between", self.outlet[a], self.inlet[b])
                counts[d] += ways * self.ends(self.outlet[seq[-1]])
            return counts
        max_dof = max(wanted, default=-1)
        joints = Counter((self.inlet[j], self.outlet[j], self.dof(j)) for j in self.joints)
        layer: Counter[tuple[Kind, int]] = Counter()  # (output kind, joints so far): ways
        for (inlet, outlet, dof), m in joints.items():
            if dof <= max_dof:
                layer[(outlet, dof)] += m * sum(n * self.count_runs("start", b, inlet) for b, n in starts.items())
        while layer:  # each step adds a joint module (>= 1 joint): at most max_dof steps
            nxt: Counter[tuple[Kind, int]] = Counter()
            for (kind, d), n in layer.items():
                if not n:
                    continue
                if d in counts:
                    counts[d] += n * self.ends(kind)
                for (inlet, outlet, dof), m in joints.items():
                    if d + dof <= max_dof:
                        nxt[(outlet, d + dof)] += n * m * self.count_runs("between", kind, inlet)
            layer = nxt
        return counts

    # -- listing -----------------------------------------------------------------------------
    def _runs(self, where: str, before: Kind, after: Kind) -> Iterable[Ids]:
        """The link runs allowed at ``where`` between kinds ``before`` and ``after``, in order."""
        return pool(lambda: self._list_runs(where, before, after), self.count_runs(where, before, after))

    def _list_runs(self, where: str, before: Kind, after: Kind) -> Iterator[Ids]:
        pattern = self.pattern(where)
        if pattern is not None:
            yield from self._pattern_runs(where, pattern, before, after)
            return
        low, high = self.lengths(where)
        for k in range(low, high + 1):  # shortest first, then in catalogue order
            if self._reaches(before, k, after):
                yield from self._extend((), before, k, after)

    def _followers_of(self, kind: Kind) -> Ids:
        """The link modules whose input meets an output of ``kind``, in catalogue order."""
        return tuple(k for k in self.links if _meets(kind, self.inlet[k]))

    def _reaches_in(self, kind: Kind, length: int, after: Kind) -> bool:
        """Whether ``length`` links can follow an output of ``kind`` and meet an input ``after``."""
        if length == 0:
            return _meets(kind, after)
        outlets = {self.outlet[k] for k in self._followers(kind)}
        return any(self._reaches(o, length - 1, after) for o in outlets)

    def _extend(self, run: Ids, kind: Kind, left: int, after: Kind) -> Iterator[Ids]:
        if left == 0:
            yield run
            return
        for link in self._followers(kind):
            outlet = self.outlet[link]
            if self._reaches(outlet, left - 1, after):
                yield from self._extend((*run, link), outlet, left - 1, after)

    def _choices(self, pattern: RunPattern, i: int) -> Choice:
        ids, optional = pattern.slots[i]
        return (*dict.fromkeys(ids), None) if optional else tuple(dict.fromkeys(ids))

    def _pattern_reaches_from(self, where: str, i: int, kind: Kind, after: Kind) -> bool:
        """Whether the slots from ``i`` on can follow an output of ``kind`` and meet ``after``."""
        pattern = self.pattern(where)
        assert pattern is not None
        if i == len(pattern.slots):
            return _meets(kind, after)
        return any(
            self._pattern_reaches(where, i + 1, kind, after)
            if c is None
            else _meets(kind, self.inlet[c]) and self._pattern_reaches(where, i + 1, self.outlet[c], after)
            for c in self._choices(pattern, i)
        )

    def _pattern_runs(self, where: str, pattern: RunPattern, before: Kind, after: Kind) -> Iterator[Ids]:
        """A whitelist's runs in the order of its slot choices (each slot's ids, then none),
        each at its first choice only (two choices may give one run)."""
        n = len(pattern.slots)

        def walk(i: int, choice: Choice, kind: Kind) -> Iterator[Ids]:
            if i == n:
                run = tuple(c for c in choice if c is not None)
                if _first_choice(pattern, run) == choice:
                    yield run
                return
            for c in self._choices(pattern, i):
                outlet = kind if c is None else self.outlet[c]
                if (c is None or _meets(kind, self.inlet[c])) and self._pattern_reaches(where, i + 1, outlet, after):
                    yield from walk(i + 1, (*choice, c), outlet)

        if self._pattern_reaches(where, 0, before, after):
            yield from walk(0, (), before)

    def allows(self, where: str, run: Ids) -> bool:
        """Whether the grammar allows ``run`` (link modules whose neighbours meet) at ``where``."""
        pattern = self.pattern(where)
        if pattern is None:
            low, high = self.lengths(where)
            return low <= len(run) <= high
        return _first_choice(pattern, run) is not None

    def sequences(self, base: str, effector: str, dof: int) -> Iterator[Ids]:
        """The joint-module sequences of ``dof`` joints that assemblies from ``base`` to
        ``effector`` have: a whitelist's in its order, else every one in catalogue order, each
        step taken only if the rest can follow."""
        end = self.inlet[effector]
        g = self.grammar
        if g.joint_sequences is not None:
            for seq in g.joint_sequences:
                if seq and sum(self.dof(j) for j in seq) == dof and all(self._gaps(base, seq, effector)):
                    yield seq
            return

        def grow(prefix: Ids, kind: Kind, left: int) -> Iterator[Ids]:
            if left == 0:
                yield prefix
                return
            where = "between" if prefix else "start"
            for j in self.joints:
                d, outlet = self.dof(j), self.outlet[j]
                if d <= left and self.count_runs(where, kind, self.inlet[j]) and self.finishes(outlet, left - d, end):
                    yield from grow((*prefix, j), outlet, left - d)

        yield from grow((), self.outlet[base], dof)

    def _gaps(self, base: str, seq: Ids, effector: str) -> list[int]:
        """The number of runs at each gap of ``base``, ``seq``, ``effector``."""
        gaps = [self.count_runs("start", self.outlet[base], self.inlet[seq[0]])]
        gaps += [self.count_runs("between", self.outlet[a], self.inlet[b]) for a, b in itertools.pairwise(seq)]
        return [*gaps, self.count_runs("end", self.outlet[seq[-1]], self.inlet[effector])]

    def block(self, base: str, seq: Ids, effector: str, dof: int) -> AssemblyBlock:
        """Every assembly of ``base``, the joint modules ``seq`` (``dof`` joints) and ``effector``."""
        gaps = [self.runs("start", self.outlet[base], self.inlet[seq[0]])]
        gaps += [self.runs("between", self.outlet[a], self.inlet[b]) for a, b in itertools.pairwise(seq)]
        gaps.append(self.runs("end", self.outlet[seq[-1]], self.inlet[effector]))
        return AssemblyBlock(base, seq, effector, tuple(gaps), dof + self.dof(base) + self.dof(effector))


def _first_choice(pattern: RunPattern, run: Ids) -> Choice | None:
    """The first slot choice (each slot's ids in order, then none) that gives ``run``, or None."""
    slots = pattern.slots
    n, m = len(slots), len(run)
    # fits[i][p]: slots i.. can give run[p:]
    fits = [[False] * (m + 1) for _ in range(n + 1)]
    fits[n][m] = True
    for i in range(n - 1, -1, -1):
        ids, optional = slots[i]
        for p in range(m + 1):
            fits[i][p] = (p < m and run[p] in ids and fits[i + 1][p + 1]) or (optional and fits[i + 1][p])
    if not fits[0][0]:
        return None
    choice: list[str | None] = []
    p = 0
    for i, (ids, _) in enumerate(slots):
        if p < m and run[p] in ids and fits[i + 1][p + 1]:
            choice.append(run[p])
            p += 1
        else:
            choice.append(None)
    return tuple(choice)


def _allows_no_joint(grammar: AssemblyGrammar) -> bool:
    return grammar.joint_sequences is None or () in grammar.joint_sequences


def _dof_range(catalog: Catalog, dof: int | None) -> range:
    low, high = catalog.grammar.dof
    if dof is None:
        return range(low, high + 1)
    return range(dof, dof + 1) if low <= dof <= high else range(0)


def count_assemblies(catalog: Catalog, dof: int | None = None) -> dict[int, int]:
    """Number of assemblies per DOF (joints counted; DOFs no assembly has are left out unless
    ``dof`` asks for one), by dynamic programming over connector kinds; nothing listed."""
    counts = _Space(catalog).per_dof(_dof_range(catalog, dof))
    return {d: n for d, n in counts.items() if n or dof is not None}


def enumerate_assemblies(catalog: Catalog, dof: int | None = None) -> Iterator[Ids]:
    """Yield the module ids of every assembly, once each, DOF ascending: each after a bounded
    amount of work, in bounded memory (see the module's docstring)."""
    for block in assembly_blocks(catalog, dof):
        yield from block.assemblies()


def assembly_blocks(catalog: Catalog, dof: int | None = None) -> Iterator[AssemblyBlock]:
    """The assemblies of :func:`enumerate_assemblies`, in its order, as blocks of one base,
    joint-module sequence and effector: a block's runs are shared, so what is computed per run (a
    bound, :func:`~modular_robots.bounds.block_speed_limits`) serves every assembly of it."""
    space = _Space(catalog)
    for d in _dof_range(catalog, dof):
        for base, effector in itertools.product(space.bases, space.effectors):
            if d == 0:
                if _allows_no_joint(space.grammar):
                    runs = space.runs("end", space.outlet[base], space.inlet[effector])
                    yield AssemblyBlock(base, (), effector, (runs,), space.dof(base) + space.dof(effector))
                continue
            for seq in space.sequences(base, effector, d):
                yield space.block(base, seq, effector, d)


def assembly_error(catalog: Catalog, ids: Ids) -> str | None:
    """Why ``ids`` is not an assembly of the catalogue's grammar (None if it is one)."""
    space = _Space(catalog)
    kinds = [space.by_id[i].kind for i in ids]
    if kinds[0] != "base":
        return f"must start with a base module, not {ids[0]} ({kinds[0]})"
    if len(ids) < 2 or kinds[-1] != "effector":
        return f"must end with an effector module, not {ids[-1]} ({kinds[-1]})"
    for position, (a, b) in enumerate(itertools.pairwise(ids), start=1):
        if not space.meets(a, b):
            out, inp = space.by_id[a].outlet, space.by_id[b].inlet
            return (
                f"position {position + 1}: {b}'s input ({inp.type} {list(inp.size)}, {inp.gender}) does not meet "
                f"{a}'s output ({out.type} {list(out.size)}, {out.gender})"
            )
    for position, kind in enumerate(kinds[1:-1], start=2):
        if kind not in ("joint", "link"):
            return f"position {position}: {ids[position - 1]} ({kind}) may only be first or last"
    dof = sum(space.dof(i) for i in ids)
    low, high = catalog.grammar.dof
    if not low <= dof <= high:
        return f"has {dof} joints; the grammar allows {low} to {high}"
    joints = [i for i, k in enumerate(kinds) if k == "joint"]
    seq = tuple(ids[i] for i in joints)
    g = space.grammar
    if g.joint_sequences is not None and seq not in g.joint_sequences:
        return f"joint modules {'-'.join(seq) or '(none)'} are not one of the grammar's joint_sequences"
    if not joints:
        ok = space.allows("end", tuple(ids[1:-1]))
        return None if ok else "its links are not a run the grammar allows before the end"
    bounds = [0, *joints, len(ids) - 1]
    where = ["start"] + ["between"] * (len(joints) - 1) + ["end"]
    for w, lo, hi in zip(where, bounds[:-1], bounds[1:]):
        run = tuple(ids[lo + 1 : hi])
        if not space.allows(w, run):
            return f"the link run {'-'.join(run) or '(none)'} after {ids[lo]} is not one the grammar allows here"
    return None
