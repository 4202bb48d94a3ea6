"""Step A for general catalogues: serial assemblies by connector compatibility.

An assembly is ``base, run, J, run, J, ..., J, run, effector``: joint modules ``J`` (their joints
summed in ``dof``), link runs between them, a run after the base and one before the effector,
each neighbour pair meeting (a male output on a female input of the same type and size). The
runs' lengths follow the grammar's ranges, or its whitelists (Timor's ``Science2019`` iterator
and its test of the Science Robotics 2019 space; see
:class:`~modular_robots.modules.AssemblyGrammar`).

Counting is dynamic programming over (last joint module, joints so far): nothing is listed.
Listing is a generator, in bounded memory: DOF ascending, then base, effector, joint modules
and the runs, each in catalogue order.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator
from functools import cache
from typing import cast

from .catalog import Catalog
from .modules import AssemblyGrammar, GeneralModule, RunPattern

__all__ = ["count_assemblies", "enumerate_assemblies", "assembly_error"]

Ids = tuple[str, ...]


class _Space:
    """The compatibility graph of a catalogue and the runs its grammar allows."""

    def __init__(self, catalog: Catalog):
        self.catalog = catalog
        grammar = catalog.grammar
        assert isinstance(grammar, AssemblyGrammar), "a general catalogue's grammar"
        self.grammar: AssemblyGrammar = grammar
        # A general catalogue's modules (its grammar is an AssemblyGrammar) are GeneralModules.
        modules = cast("tuple[GeneralModule, ...]", catalog.modules)
        self.by_id: dict[str, GeneralModule] = {m.id: m for m in modules}
        kinds: dict[str, list[str]] = {"base": [], "joint": [], "link": [], "effector": []}
        for m in modules:
            kinds[m.kind].append(m.id)
        self.bases, self.joints, self.links, self.effectors = (
            tuple(kinds[k]) for k in ("base", "joint", "link", "effector")
        )
        self.run = cache(self._run)

    def meets(self, a: str, b: str) -> bool:
        return self.by_id[a].outlet.meets(self.by_id[b].inlet)

    def _chains(self, ids: Ids) -> bool:
        return all(self.meets(a, b) for a, b in itertools.pairwise(ids))

    def _run(self, where: str, before: str, after: str) -> tuple[Ids, ...]:
        """Every link run allowed at ``where`` between module ``before`` and module ``after``."""
        g = self.grammar
        pattern: RunPattern | None = {"between": g.between_joints, "end": g.before_end}.get(where)
        if pattern is not None:
            choices = [(*ids, None) if optional else ids for ids, optional in pattern.slots]  # None: no module
            runs = (tuple(x for x in combo if x is not None) for combo in itertools.product(*choices))
            candidates: Iterable[Ids] = dict.fromkeys(runs)  # a run listed twice by two slot choices counts once
        else:
            low, high = {"between": g.links_between_joints, "start": g.links_before_first_joint}.get(
                where, g.links_after_last_joint
            )
            candidates = (r for k in range(low, high + 1) for r in itertools.product(self.links, repeat=k))
        return tuple(r for r in candidates if self._chains((before, *r, after)))

    def joint_dof(self, joint_id: str) -> int:
        return self.by_id[joint_id].dof


def _dof_range(catalog: Catalog, dof: int | None) -> range:
    low, high = catalog.grammar.dof
    if dof is None:
        return range(low, high + 1)
    return range(dof, dof + 1) if low <= dof <= high else range(0)


def count_assemblies(catalog: Catalog, dof: int | None = None) -> dict[int, int]:
    """Number of assemblies per DOF (joints counted; DOFs no assembly has are left out unless
    ``dof`` asks for one), by dynamic programming; nothing listed."""
    space = _Space(catalog)
    wanted = _dof_range(catalog, dof)
    counts = dict.fromkeys(wanted, 0)
    for base, effector in itertools.product(space.bases, space.effectors):
        if 0 in counts and _allows_no_joint(space):
            counts[0] += len(space.run("end", base, effector))  # base, one run, effector
        for d, n in _joint_chains(space, base, effector, max(wanted, default=-1)).items():
            if d in counts and d > 0:
                counts[d] += n
    return {d: n for d, n in counts.items() if n or dof is not None}


def _allows_no_joint(space: _Space) -> bool:
    sequences = space.grammar.joint_sequences
    return sequences is None or () in sequences


def _joint_chains(space: _Space, base: str, effector: str, max_dof: int) -> dict[int, int]:
    """Assemblies from ``base`` to ``effector`` with >= 1 joint module, per DOF."""
    g = space.grammar
    out: dict[int, int] = {}
    if g.joint_sequences is not None:
        for seq in g.joint_sequences:
            if not seq:
                continue
            n = len(space.run("start", base, seq[0])) * len(space.run("end", seq[-1], effector))
            for a, b in itertools.pairwise(seq):
                n *= len(space.run("between", a, b))
            d = sum(space.joint_dof(j) for j in seq)
            if g.dof[0] <= d <= g.dof[1]:
                out[d] = out.get(d, 0) + n
        return out
    # f[(joint, dof)]: ways to reach joint module ``joint`` with ``dof`` joints so far
    layer = {}
    for j in space.joints:
        n = len(space.run("start", base, j))
        if n and space.joint_dof(j) <= max_dof:
            layer[(j, space.joint_dof(j))] = n
    while layer:
        nxt: dict[tuple[str, int], int] = {}
        for (j, d), n in layer.items():
            ends = len(space.run("end", j, effector))
            if ends:
                out[d] = out.get(d, 0) + n * ends
            for k in space.joints:
                dk = d + space.joint_dof(k)
                if dk <= max_dof:
                    runs = len(space.run("between", j, k))
                    if runs:
                        nxt[(k, dk)] = nxt.get((k, dk), 0) + n * runs
        layer = nxt
    return out


def enumerate_assemblies(catalog: Catalog, dof: int | None = None) -> Iterator[Ids]:
    """Yield the module ids of every assembly, once each, DOF ascending (bounded memory)."""
    space = _Space(catalog)
    for d in _dof_range(catalog, dof):
        for base, effector in itertools.product(space.bases, space.effectors):
            if d == 0:
                if _allows_no_joint(space):
                    for run in space.run("end", base, effector):
                        yield (base, *run, effector)
                continue
            for seq in _sequences(space, d):
                yield from _fill(space, base, seq, effector)


def _sequences(space: _Space, dof: int) -> Iterator[Ids]:
    g = space.grammar
    if g.joint_sequences is not None:
        yield from (s for s in g.joint_sequences if s and sum(space.joint_dof(j) for j in s) == dof)
        return

    def grow(prefix: Ids, left: int) -> Iterator[Ids]:
        if left == 0:
            yield prefix
            return
        for j in space.joints:
            if space.joint_dof(j) <= left and (not prefix or space.run("between", prefix[-1], j)):
                yield from grow((*prefix, j), left - space.joint_dof(j))

    yield from grow((), dof)


def _fill(space: _Space, base: str, seq: Ids, effector: str) -> Iterator[Ids]:
    gaps = [space.run("start", base, seq[0])]
    gaps += [space.run("between", a, b) for a, b in itertools.pairwise(seq)]
    gaps.append(space.run("end", seq[-1], effector))
    for runs in itertools.product(*gaps):
        ids = [base, *runs[0]]
        for joint, run in zip(seq, runs[1:]):
            ids += [joint, *run]
        yield (*ids, effector)


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
    dof = sum(space.by_id[i].dof for i in ids)
    low, high = catalog.grammar.dof
    if not low <= dof <= high:
        return f"has {dof} joints; the grammar allows {low} to {high}"
    joints = [i for i, k in enumerate(kinds) if k == "joint"]
    seq = tuple(ids[i] for i in joints)
    g = space.grammar
    if g.joint_sequences is not None and seq not in g.joint_sequences:
        return f"joint modules {'-'.join(seq) or '(none)'} are not one of the grammar's joint_sequences"
    if not joints:
        ok = tuple(ids[1:-1]) in space.run("end", ids[0], ids[-1])
        return None if ok else "its links are not a run the grammar allows before the end"
    bounds = [0, *joints, len(ids) - 1]
    where = ["start"] + ["between"] * (len(joints) - 1) + ["end"]
    for w, lo, hi in zip(where, bounds[:-1], bounds[1:]):
        run = tuple(ids[lo + 1 : hi])
        if run not in space.run(w, ids[lo], ids[hi]):
            return f"the link run {'-'.join(run) or '(none)'} after {ids[lo]} is not one the grammar allows here"
    return None
