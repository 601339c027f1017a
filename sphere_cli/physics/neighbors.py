"""Neighbour search (the prepare hook): keep the half Verlet list and its reverse list valid,
rebuilding them when some particle has moved half the skin, and growing their capacity when a
row overflows."""

from __future__ import annotations

import numpy as np

from ..config.memory import CELLS_PER_PARTICLE, DENSE_FLOOR
from ..errors import NumericalError
from ..kernels.neighbors import (
    build_lists,
    build_reverse,
    carry_springs,
    carry_springs_from_rows,
    cell_index,
    counting_sort,
    drop_ghost_pairs,
    row_starts,
    sort_occupied,
)
from ..state import NeighborList, State
from .module import Module

INITIAL_CAPACITY = 8  # half rows: a settled monodisperse bed lists at most ~10 (the list grows on overflow)
# Rows at least SHRINK_SLACK wider than the longest are narrowed to longest + HEADROOM (never
# below INITIAL_CAPACITY), but only once QUIET_BUILDS builds have passed without growth: while a
# packing compacts, its rows grow build after build, and narrowing between growths made every
# growth redo the build (frictionless packing test: 19 -> 25 s).
SHRINK_SLACK = 4
HEADROOM = 2
QUIET_BUILDS = 20
# the packed springs are allocated for this many times the pairs listed (rebuilds add or drop a
# few pairs; more than that reallocates them)
SPRING_ROOM = 1.25
# cells along one axis at most (2^60 cells in all fit the int64 cell numbers); more would be
# cells wider than needed, which costs pairs checked, never pairs missed
AXIS_CELLS = 2**20


def allocate_neighbor_list(n: int, skin: float, capacity: int | None = None) -> NeighborList:
    if capacity is None:
        capacity = INITIAL_CAPACITY  # read at call time (tests change it)
    return NeighborList(
        skin=skin,
        nbr=np.zeros((n, capacity), dtype=np.int32),
        nbr_count=np.zeros(n, dtype=np.int32),
        start=np.zeros(n + 1, dtype=np.int64),
        hist=np.zeros((0, 3)),
        ref_pos=np.zeros((n, 3)),
        rev=np.zeros((n, capacity), dtype=np.int32),
        rev_count=np.zeros(n, dtype=np.int32),
    )


def search_cells(length: np.ndarray, largest: float, skin: float) -> np.ndarray:
    """Cells along each axis: as many as fit cubes of two largest radii plus the skin (a pair
    that can touch before the next build lies in neighbouring cells), at least 1, at most AXIS_CELLS."""
    reach = 2.0 * largest + skin
    return np.clip(np.floor(np.asarray(length, dtype=float) / reach), 1, AXIS_CELLS).astype(np.int64)


class NeighborSearch(Module):
    name = "neighbors"

    def __init__(self, state: State, springs: bool = True):
        box, p, nl = state.box, state.particles, state.neighbors
        # the pairs carry tangential springs (nl.hist) only when some contact has friction;
        # without, nl.hist has no rows and the kernels read none
        self.springs = springs
        self.ncell = search_cells(box.length, float(p.radius.max(initial=0.0)), nl.skin)
        self.cell_size = box.length / self.ncell
        self.cell_of = np.zeros(p.count, dtype=np.int64)
        cells = float(np.prod(self.ncell.astype(float)))
        self.dense = cells <= CELLS_PER_PARTICLE * p.count + DENSE_FLOOR
        self.cell_start = np.zeros((int(cells) if self.dense else p.count) + 1, dtype=np.int64)
        self.cell_key = np.zeros(0 if self.dense else p.count, dtype=np.int64)
        self.order = np.zeros(p.count, dtype=np.int64)
        self.threshold2 = (0.5 * nl.skin) ** 2
        self.builds_since_growth = QUIET_BUILDS + 1  # no growth seen yet (a restore sets the checkpoint's)
        self._spare_like(nl)

    @staticmethod
    def longest(needed: int) -> int:
        """The longest row that sets the rows' width: this list's own (a scene split across
        ranks sets the longest over every rank: physics/rank_steps.py)."""
        return needed

    def _spare_like(self, nl: NeighborList):
        self.spare_nbr = np.zeros_like(nl.nbr)
        self.spare_count = np.zeros_like(nl.nbr_count)
        self.spare_start = np.zeros_like(nl.start)
        self.spare_hist = np.zeros_like(nl.hist)

    def prepare(self, state: State) -> None:
        """Rebuild once some particle has moved half the skin (measured by the drift just
        before, physics/motion.py)."""
        if state.neighbors.moved2 > self.threshold2:
            self.rebuild(state)

    def rebuild(self, state: State, received: tuple | None = None, owned: np.ndarray | None = None) -> None:
        """The list built again from the positions, each pair listed before keeping its spring.
        On a rank of a split run (physics/rank_steps.py) the springs come from the half rows it
        `received` (global indices, each row's first place and length, partners by global index,
        springs: kernels/neighbors.py carry_springs_from_rows) instead, and
        the pairs of two particles it does not `own` are left out."""
        box, p, nl = state.box, state.particles, state.neighbors
        cell_index(p.pos, box.lower, self.cell_size, self.ncell, self.cell_of)
        if self.dense:
            counting_sort(self.cell_of, self.cell_start.size - 1, self.cell_start, self.order)
            used = -1
        else:
            used = sort_occupied(self.cell_of, self.order, self.cell_key, self.cell_start)
        while True:
            build_lists(*self.list_arguments(state, used))
            needed = self.longest(int(self.spare_count.max()) if p.count else 0)
            if needed <= nl.nbr.shape[1]:
                break
            self._grow(nl, needed)
            self.builds_since_growth = 0
        pairs = int(row_starts(self.spare_count, self.spare_nbr.shape[1], self.spare_start))
        if self.springs:
            if self.spare_hist.shape[0] < pairs:
                self.spare_hist = np.zeros((int(SPRING_ROOM * pairs) + 64, 3))
            new_rows = (self.spare_nbr, self.spare_count, self.spare_start, self.spare_hist)
            if received is None:
                carry_springs(nl.nbr, nl.nbr_count, nl.start, nl.hist, *new_rows)
            else:
                carry_springs_from_rows(*received, *new_rows)
        nl.nbr, self.spare_nbr = self.spare_nbr, nl.nbr
        nl.nbr_count, self.spare_count = self.spare_count, nl.nbr_count
        nl.start, self.spare_start = self.spare_start, nl.start
        nl.hist, self.spare_hist = self.spare_hist, nl.hist
        self.builds_since_growth += 1
        quiet = self.builds_since_growth > QUIET_BUILDS
        if quiet and nl.nbr.shape[1] >= needed + SHRINK_SLACK and nl.nbr.shape[1] > INITIAL_CAPACITY:
            # rows far wider than the longest one (a bed that has settled, a smaller skin):
            # narrower rows take less memory (the springs are packed whatever the width)
            self._resize(nl, max(needed + HEADROOM, INITIAL_CAPACITY))
        nl.ref_pos[:] = p.pos
        nl.moved2 = 0.0
        nl.builds += 1
        if owned is not None:
            drop_ghost_pairs(owned, nl.nbr, nl.nbr_count, nl.start, nl.hist, self.springs)
        self._reverse(nl)

    def list_arguments(self, state: State, used: int = -1) -> tuple:
        """The arguments of build_lists (kernels/neighbors.py) into the spare rows, the cells
        sorted (`used`: the occupied cells of a sparse grid, -1 for a dense one)."""
        box, p, nl = state.box, state.particles, state.neighbors
        return (
            p.pos,
            p.radius,
            box.length,
            box.periodic,
            self.ncell,
            self.cell_of,
            self.cell_start,
            self.cell_key,
            used,
            self.order,
            nl.skin,
            self.spare_nbr,
            self.spare_count,
        )

    @staticmethod
    def _reverse(nl: NeighborList) -> None:
        """Rebuild the reverse list from the half rows, widening it if a row overflows."""
        if nl.start[-1] >= 2**31:
            raise NumericalError(
                f"the neighbour list holds {nl.start[-1]} pairs, more than the 2^31 its int32 indices "
                "address; use fewer particles per run or a smaller neighbor_skin"
            )
        while True:
            longest = build_reverse(nl.nbr, nl.nbr_count, nl.start, nl.rev, nl.rev_count)
            if longest <= nl.rev.shape[1]:
                return
            nl.rev = np.zeros((nl.nbr.shape[0], max(longest + 4, int(1.5 * nl.rev.shape[1]))), dtype=np.int32)

    def _grow(self, nl: NeighborList, needed: int) -> None:
        """Widen every row to hold `needed` (plus headroom), keeping the current list intact."""
        self._resize(nl, max(needed + 4, int(1.5 * nl.nbr.shape[1])))

    def _resize(self, nl: NeighborList, capacity: int) -> None:
        """Rows of `capacity` slots holding the current list (at least its longest row; the
        packed springs and row starts stay as they are)."""
        n = nl.nbr.shape[0]
        nbr = np.zeros((n, capacity), dtype=np.int32)
        width = min(nl.nbr.shape[1], capacity)
        nbr[:, :width] = nl.nbr[:, :width]
        nl.nbr = nbr
        self.spare_nbr = np.zeros_like(nl.nbr)

    def prognostic_state(self, state: State) -> dict:
        """The list with its springs in rows (N,C,3) like the rows of nbr: the checkpoint's
        layout does not depend on how the springs are packed (no springs without friction)."""
        nl = state.neighbors
        arrays = {name: getattr(nl, name) for name in NeighborList.PROGNOSTIC if name != "hist"}
        # the slots past a row's end hold what earlier builds left there: zeros instead, so that
        # a checkpoint holds the list and nothing else (one written on many ranks is bitwise one
        # rank's)
        arrays["nbr"] = np.where(listed_slots(nl.nbr, nl.nbr_count), nl.nbr, 0).astype(nl.nbr.dtype)
        if self.springs:
            arrays["hist"] = spring_rows(nl)
        arrays["skin"] = np.float64(nl.skin)
        # when the rows may narrow next: without it a resumed run narrows them at another build
        # than the run it continues, and its checkpoints differ (the same pairs, other widths)
        arrays["builds_since_growth"] = np.int64(self.builds_since_growth)
        return arrays

    def restore(self, state: State, arrays: dict) -> None:
        """Restore the list; with a different skin than it was built for (a resume may change
        simulation.neighbor_skin) rebuild it at once, carrying the history across."""
        nl = state.neighbors
        for name in NeighborList.PROGNOSTIC:
            if name != "hist":
                setattr(nl, name, np.array(arrays[name]))
        row_starts(nl.nbr_count, nl.nbr.shape[1], nl.start)
        if self.springs:
            _pack_springs(nl, arrays["hist"])
        self._spare_like(nl)
        self._reverse(nl)
        self.builds_since_growth = int(arrays.get("builds_since_growth", QUIET_BUILDS + 1))
        if float(arrays["skin"]) != nl.skin:
            self.rebuild(state)


def listed_slots(nbr: np.ndarray, nbr_count: np.ndarray) -> np.ndarray:
    """(N,C) bool: the slots of nbr that hold a listed pair."""
    cap = nbr.shape[1]
    return np.arange(cap)[None, :] < np.minimum(nbr_count, cap)[:, None]


def spring_rows(nl: NeighborList) -> np.ndarray:
    """The packed springs laid out like nbr, (N,C,3), zero in the unused slots."""
    rows = np.zeros(nl.nbr.shape + (3,))
    rows[listed_slots(nl.nbr, nl.nbr_count)] = nl.hist[: nl.start[-1]]
    return rows


def _pack_springs(nl: NeighborList, rows: np.ndarray) -> None:
    """Pack the springs in rows (N,C,3) of a checkpoint into nl.hist (row starts set)."""
    pairs = int(nl.start[-1])
    hist = np.zeros((int(SPRING_ROOM * pairs) + 64, 3))
    hist[:pairs] = rows[listed_slots(nl.nbr, nl.nbr_count)]
    nl.hist = hist
