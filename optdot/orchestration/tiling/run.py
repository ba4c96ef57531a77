"""Run the tile tasks of :mod:`optdot.orchestration.tiling.tasks` as one task graph, in process or
on Dask.

Every tile's throw and its deposit come first (the panel-wide field the first relaxation
needs is solved from all of them; the throws are held until their relaxations take them,
16 B a dot). Then tasks are submitted in waves along the panel's rows (relax row j, its
seams, its merge, its correction, then the guarantee pass of the rows behind it), each
task's Dask priority its place in that order (:class:`OnDask`), so only a few rows of
relaxed and corrected tiles are held at once (the merged dots, 32 B a dot, are kept to
the end: see :func:`run_tiles`). With a wide correction pass (the default formulation)
the correction is split by a barrier: every tile's first pass and its deposit, the wide
field from all of them, then row by row the first passes moved along it and the
guarantee passes; the first passes are held across the barrier and kept to the end in
place of the merged dots, which are let go: on a panel whose first passes would take
more than :data:`HOLD_SHARE` of the workers' memory, only their positions (``SLIM``: 16 B
a dot, not 32), each tile's containers thrown again after it
(:func:`optdot.orchestration.tiling.tasks.containers`; the same bytes either way). The wide pass
is solved as many times as the formulation says (``lowpass_last_steps``), each time from
where the dots stand: each round after the first deposits every tile's first pass moved
along the fields before it (``STEP``: the moves are made again from the first pass,
which is held anyway, rather than a copy of every tile's dots held across each
barrier), and its field is a barrier; the corrected dots are the first pass moved along
every round's field in turn. Finished tiles are handed to ``sink`` one at a time, in the
order they finish; what the sink writes depends only on the tile, so the output is the
same whatever the order.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ...config.job import Job, OptimizeParams
from ...geometry.density import DensityMap
from ...geometry.shapes import Footprints
from ...relax.lowpass import CoarseField
from ...runtime.cluster import single_threaded
from ...runtime.stop import check_interrupt
from ...stages import wide_rounds
from ..job_settings import stage_settings
from .plan import TilePlan, plan_tiles
from .tasks import (
    FinalDots,
    TileDots,
    apply_seams,
    coarse_task,
    correct_tile,
    deposit_task,
    first_positions,
    held_dots,
    initial_task,
    legalize_tile,
    relax_seams,
    relax_tile,
    wide_deposit_task,
    wide_shift,
    wide_step,
    wide_task,
)

#: ``sink(tile, xy, footprints)``: a finished tile's final positions ``[n, 2]`` mm and
#: its dots' footprints (:attr:`FinalDots.footprints`).
Sink = Callable[[tuple[int, int], np.ndarray, Footprints], None]
#: ``progress(fraction done, line)``.
TileProgress = Callable[[float, str], None]

#: Share of a tile's time each kind of task takes (for the ETA), measured at 150k dots.
_WEIGHTS = {"relax": 1.0, "seams": 0.25, "merge": 0.0, "correct": 0.2, "shift": 0.01, "legal": 0.08}

#: Kinds of task in the schedule, in the order a wave submits them (the guarantee
#: passes: ``LEGAL`` and ``LEGAL + 1``, by row parity).
INITIAL, DEPOSIT, COARSE, RELAX, SEAMS, MERGE, CORRECT, WDEPOSIT, SLIM, WIDE, STEP, SHIFT, LEGAL = (
    range(-3, 10)
)
#: Names of the kinds in :func:`needed`.
KIND_NAMES = {
    INITIAL: "initial", DEPOSIT: "deposit", COARSE: "coarse", RELAX: "relax", SEAMS: "seams",
    MERGE: "merge", CORRECT: "correct", WDEPOSIT: "wdeposit", SLIM: "slim", WIDE: "wide",
    STEP: "step", SHIFT: "shift",
}  # fmt: skip


def wide_steps(job: Job) -> int:
    """Rounds of the wide pass a tiled run of ``job`` makes (0 without a wide pass;
    :func:`optdot.stages.wide_rounds`)."""
    return wide_rounds(stage_settings(job))


def field_name(r: int) -> str:
    """The name a resumable run keeps round ``r``'s wide field under (``"wide"``,
    ``"wide2"``, ...)."""
    return "wide" if r == 0 else f"wide{r + 1}"


class FieldStore(Protocol):
    """Where a resumable run keeps its panel-wide fields (``"coarse"``, ``"wide"``) as
    named arrays, so that a resumed run need not remake them from every tile
    (:class:`optdot.io.dataset_write.DatasetWriter`: its staging directory)."""

    def read_extra(self, name: str) -> dict[str, np.ndarray] | None:
        """What an interrupted run of the same job kept under ``name``, or None."""

    def write_extra(self, name: str, arrays: dict[str, np.ndarray]) -> None:
        """Keep ``arrays`` under ``name``."""


def _value(value: Any) -> Any:
    """A task that returns what it was given (:meth:`OnDask.share`)."""
    return value


def _run(fn: Callable, *args: Any) -> Any:
    """A task: numba on one thread, then ``fn(*args)``."""
    single_threaded()
    return fn(*args)


def _legal(job: Job, plan: TilePlan, dots: TileDots, *neighbours: TileDots | FinalDots):
    return legalize_tile(job, plan, dots, [held_dots(job, n) for n in neighbours])


class InProcess:
    """Runs each task when it is submitted (tests, and tiles without a cluster).

    Attributes:
        memory: bytes the run may hold at once (:func:`slim_first_passes`; 0: no bound).
    """

    memory: int = 0

    def __init__(self, memory: int = 0) -> None:
        self.memory = memory

    def share(self, value: Any) -> Any:
        return value

    def submit(self, kind: str, key: str, fn: Callable, *args: Any) -> Any:
        return fn(*args)

    def finished(self, handles: list[Any]):
        """The handles in order; the list is emptied (each handed over once)."""
        items = handles[::-1]
        handles.clear()
        while items:
            yield items.pop()

    def result(self, handle: Any) -> Any:
        return handle


@dataclass
class OnDask:
    """Submits tasks to a ``distributed.Client``; a task whose worker dies is retried.

    Each task's priority is its place in the order of submission (the first highest):
    Dask's own order for tasks submitted within ``fifo_timeout`` of each other (100 ms:
    a whole schedule) is its graph order, which for separate submissions follows no
    row. With the wide pass every correction is ready at once when its field is made,
    and without priorities the workers took them in no order, corrected tiles far
    ahead of their guarantee passes (notebook: 44 corrected against 30 final at the
    peak)."""

    client: Any
    memory: int = 0  # the workers' memory together, bytes (0: not known)
    retries: int = 2
    run_id: str = field(default_factory=lambda: uuid.uuid4().hex[:8])
    submitted: int = 0
    shared: int = 0

    def share(self, value: Any) -> Any:
        """A handle to ``value`` that every task may take: the result of a task that
        returns it. Its one copy goes to the scheduler with the task; a worker that needs
        it fetches it from the worker holding it, and if that worker is lost the
        scheduler runs the task again elsewhere. Not ``scatter(broadcast=True)``: its
        replication to every worker at times never finished (a run hung at its first
        share, every process idle, on a loaded machine; dask/distributed#4907), and a
        scattered value whose only holder dies cannot be made again."""
        import dask

        self.shared += 1
        with dask.config.set({"distributed.admin.large-graph-warning-threshold": "2GiB"}):
            return self.client.submit(
                _value, value, key=f"optdot-shared-{self.shared}-{self.run_id}",
                priority=1, retries=self.retries, pure=False,
            )  # fmt: skip

    def submit(self, kind: str, key: str, fn: Callable, *args: Any) -> Any:
        self.submitted += 1
        return self.client.submit(
            _run, fn, *args, key=f"optdot-{kind}-{key}-{self.run_id}", retries=self.retries,
            priority=-self.submitted,
        )  # fmt: skip

    def finished(self, handles: list[Any]):
        """The handles as they finish; the wait wakes every 0.1 s, so a stop asked for
        by a signal is honoured within that, not after the running tile. The list is
        emptied: from here ``as_completed`` holds each future until it is handed over,
        and the caller drops it after (its result is then freed once no task needs it)."""
        from distributed import as_completed

        done = as_completed(handles)
        handles.clear()
        while not done.is_empty():
            batch = done.next_batch(block=False)
            if not batch:
                check_interrupt()
                time.sleep(0.1)
            yield from batch

    def result(self, handle: Any) -> Any:
        return handle.result()


@dataclass
class TiledRun:
    """What a tiled run did: the plan, the dots written per tile, seconds."""

    plan: TilePlan
    counts: dict[tuple[int, int], int]
    seconds: float


#: Share of the workers' memory the first correction passes may take while the wide pass
#: holds them (32 B a dot): past it only their positions are held (16 B a dot) and each
#: tile's containers are thrown again after the barrier
#: (:func:`optdot.orchestration.tiling.tasks.containers`, ~0.4 µs a dot). The 55-inch TV's 114M
#: dots on
#: 2 workers of 9.4 GiB: 3.6 GB held, peak 6.75 GiB; slim, 5.61 GiB. The monitor's 27M
#: dots (0.9 GB) keep them.
HOLD_SHARE = 0.1


def slim_first_passes(plan: TilePlan, memory: int) -> bool:
    """Whether a run of ``plan`` on workers of ``memory`` bytes together (0: not known,
    nothing is slimmed) holds only its first passes' positions across the wide pass."""
    return memory > 0 and 32 * int(plan.quotas.sum()) > HOLD_SHARE * memory


def needed(
    plan: TilePlan,
    todo: set[tuple[int, int]],
    wide: bool = False,
    given: frozenset[str] = frozenset(),
    steps: int = 1,
    slim: bool = False,
) -> dict[str, set[tuple[int, int]]]:
    """The tasks that tiles ``todo`` need, when every other tile is finished (a resumed
    run): ``{"initial", "deposit", "coarse", "relax", "seams", "merge", "correct",
    "wdeposit", "wide", "step", "shift", "legal": tiles or grid points}`` (``coarse``,
    ``wide``: ``{(0, 0)}``, one task a round, or empty; ``wdeposit``, ``wide`` and
    ``step`` stand for every round of the wide pass's ``steps``).

    A tile's guarantee pass holds its earlier-colour neighbours' final dots (read from
    the finished parts when finished) and its later-colour neighbours' corrected dots
    (made again: the uninterrupted run held those too). With ``wide`` (the job's
    correction has a wide pass) corrected dots are a tile's first pass moved along the
    wide field, which needs every tile's first pass; a first pass needs the merged dots
    of its tile and the tiles around it, merged dots the tile's relaxation and its
    corners' seams, a seam square the relaxation of the tiles meeting there, a relaxation
    the initial dots of the tiles around it and the panel-wide field, which needs every
    tile's initial dots (cheap: a throw). A field in ``given`` (``"coarse"``, ``"wide"``:
    kept by the interrupted run) needs none of that; the wide pass's fields count only
    when every round's is given (:func:`field_name`), and the rounds before the last then
    move only the held tiles. Every task is a pure function of the job and its inputs,
    so what is made again is what was made before.
    """
    have_wide = all(field_name(r) in given for r in range(max(1, steps)))
    held = set(todo)
    for t in todo:
        c = plan.colour(*t)
        held |= {u for u in plan.neighbours(*t) if plan.colour(*u) > c}
    correct = set(plan.tiles()) if wide and held and not have_wide else held
    merge = set(correct)
    for t in correct:
        merge |= set(plan.neighbours(*t))
    corner_set = set(plan.corners())
    seams = {(i + a, j + b) for i, j in merge for b in (0, 1) for a in (0, 1)} & corner_set
    relax = set(merge)
    for g in seams:
        relax |= set(plan.corner_tiles(*g))
    initial = set(relax)
    for t in relax:
        initial |= set(plan.neighbours(*t))
    deposit = set(plan.tiles()) if relax and "coarse" not in given else set()
    return {
        "initial": initial | deposit,
        "deposit": deposit,
        "coarse": {(0, 0)} if deposit else set(),
        "relax": relax,
        "seams": seams,
        "merge": merge,
        "correct": correct,
        "wdeposit": correct if wide and not have_wide else set(),
        "slim": correct if wide and slim else set(),
        "wide": {(0, 0)} if wide and held and not have_wide else set(),
        "step": correct if wide and steps > 1 and not have_wide else set(),
        "shift": held if wide else set(),
        "legal": set(todo),
    }


def run_tiles(
    job: Job,
    plan: TilePlan,
    executor: InProcess | OnDask,
    sink: Sink,
    progress: TileProgress | None = None,
    finished: dict[tuple[int, int], Callable[[], FinalDots]] | None = None,
    fields: FieldStore | None = None,
) -> TiledRun:
    """Generate ``job`` tile by tile on ``executor``, handing each finished tile to ``sink``.

    ``finished``: tiles already done (a resumed run), each with a loader of its final
    dots; only the tasks the other tiles need are run (:func:`needed`), and the sink
    gets only the other tiles. ``fields``: where the panel-wide fields are kept as they
    are made, and found when an interrupted run made them (then not made again).

    Raises:
        GuaranteeError: a tile could not be made legal.
        GeometryError: a tile's dots do not fit inside the outline.
    """
    t0 = time.perf_counter()
    jobf = executor.share(job)
    tiles = plan.tiles()
    corners = plan.corners()
    corner_set = set(corners)
    corners_of = {
        t: [c for c in ((t[0] + a, t[1] + b) for b in (0, 1) for a in (0, 1)) if c in corner_set]
        for t in tiles
    }
    steps = wide_steps(job)
    wide = steps > 0
    slim = wide and slim_first_passes(plan, executor.memory)
    # with a wide pass: every tile's first correction pass and its deposit, then the
    # wide field (a barrier: it needs all of them); each further round deposits every
    # tile's first pass moved along the fields so far, then its field (a barrier); then
    # row by row each tile's first pass moved along every field (the corrected dots)
    # and the guarantee passes
    first = plan.ny + 3  # the wave of the first wide field
    after = first + 2 * (steps - 1) if wide else 0  # the wave of the last
    # (wave, kind, row, colour, tile, round of the wide pass)
    schedule: list[tuple[int, int, int, int, tuple[int, int], int]] = []
    for i, j in tiles:
        # every tile's initial dots and their deposit first: the panel-wide field that
        # the first relaxation needs is solved from all of them
        schedule.append((-2, INITIAL, j, 0, (i, j), 0))
        schedule.append((-2, DEPOSIT, j, 0, (i, j), 0))
        schedule.append((j + 1, RELAX, j, 0, (i, j), 0))  # needs initial j-1..j+1
    schedule.append((-1, COARSE, 0, 0, (0, 0), 0))
    for r in range(steps):
        schedule.append((first + 2 * r, WIDE, 0, 0, (0, 0), r))
    for i, j in corners:
        schedule.append((j + 1, SEAMS, j, 0, (i, j), 0))  # seams of corner row j: relax j-1, j
    for i, j in tiles:
        schedule.append((j + 2, MERGE, j, 0, (i, j), 0))  # merge: needs corners j, j+1
        schedule.append((j + 3, CORRECT, j, 0, (i, j), 0))  # correct: needs merged j-1..j+1
        if wide:
            schedule.append((j + 3, WDEPOSIT, j, 0, (i, j), 0))
            if slim:  # what is held of the first pass
                schedule.append((j + 3, SLIM, j, 0, (i, j), 0))
            for r in range(1, steps):  # moved along rounds 0..r-1's fields, deposited
                schedule.append((first + 2 * r - 1, STEP, j, 0, (i, j), r))
            schedule.append((after + j + 1, SHIFT, j, 0, (i, j), steps - 1))
        c = plan.colour(i, j)
        schedule.append((after + j + 4 + (j % 2), LEGAL + (j % 2), j, c, (i, j), 0))  # guarantee
    finished = finished or {}
    given = {}
    names = ["coarse", *(field_name(r) for r in range(steps))]
    for name in names if fields is not None else ():
        arrays = fields.read_extra(name)
        if arrays is not None:
            given[name] = CoarseField.from_arrays(arrays)
    if finished or given:
        need = needed(plan, set(tiles) - set(finished), wide, frozenset(given), steps, slim)
        schedule = [e for e in schedule if e[4] in need[KIND_NAMES.get(e[1], "legal")]]
    schedule.sort()
    held: dict = {}

    def loaded(u: tuple[int, int]):
        """A finished tile's final dots, read once and shared with the workers."""
        if u not in held:
            held[u] = executor.share(finished[u]())
        return held[u]

    initial: dict = {}
    deposits: dict = {}
    coarse = executor.share(given["coarse"]) if "coarse" in given else None
    relaxed: dict = {}
    seams: dict = {}
    merged: dict = {}
    firsts: dict = {}  # the first correction pass (the corrected dots, without a wide pass)
    slims: dict = {}  # its positions alone, held across the wide pass's barriers (slim)
    held_first = slims if slim else firsts  # what the wide pass's rounds start from
    wdeposits: dict = {}  # (round, tile): deposit on the wide lattice
    have_wide = all(field_name(r) in given for r in range(steps))
    wide_fields = {r: executor.share(given[field_name(r)]) for r in range(steps) if have_wide}
    made = {}  # the fields made here, to keep for a resumed run
    corrected: dict = {}
    final: dict = {}
    kind_of: dict[Any, str] = {}
    for _, kind, _, _, (i, j), r in schedule:
        key = f"{i}-{j}"
        if kind == INITIAL:
            initial[i, j] = executor.submit("initial", key, initial_task, jobf, plan, i, j)
        elif kind == DEPOSIT:
            deposits[i, j] = executor.submit("deposit", key, deposit_task, jobf, initial[i, j])
        elif kind == COARSE:
            parts = [deposits[t] for t in tiles]
            coarse = made["coarse"] = executor.submit("coarse", "panel", coarse_task, jobf, *parts)
        elif kind == RELAX:
            around = [initial[u] for u in plan.neighbours(i, j)]
            h = executor.submit(
                "relax", key, relax_tile, jobf, plan, coarse, i, j, initial[i, j], *around
            )
            relaxed[i, j] = h
            kind_of[id(h)] = "relax"
        elif kind == SEAMS:
            parts = [relaxed[t] for t in plan.corner_tiles(i, j)]
            seams[i, j] = executor.submit("seams", key, relax_seams, jobf, plan, i, j, parts)
        elif kind == MERGE:
            results = [seams[c] for c in corners_of[i, j]]
            merged[i, j] = executor.submit("merge", key, apply_seams, relaxed[i, j], results)
        elif kind == CORRECT:
            around = [merged[u] for u in plan.neighbours(i, j)]
            h = executor.submit("correct", key, correct_tile, jobf, plan, merged[i, j], *around)
            firsts[i, j] = h
            if not wide:
                corrected[i, j] = h
            kind_of[id(h)] = "correct"
        elif kind == WDEPOSIT:
            h = executor.submit("wdeposit", key, wide_deposit_task, jobf, firsts[i, j])
            wdeposits[0, (i, j)] = h
        elif kind == SLIM:
            slims[i, j] = executor.submit("slim", key, first_positions, firsts[i, j])
        elif kind == WIDE:
            parts = [wdeposits[r, t] for t in tiles]
            name = field_name(r)
            h = executor.submit(name, "panel", wide_task, jobf, *parts)
            wide_fields[r] = made[name] = h
        elif kind == STEP:
            fields_so_far = [wide_fields[k] for k in range(r)]
            h = executor.submit(
                f"wdeposit{r}", key, wide_step, jobf, plan, coarse, i, j, held_first[i, j],
                *fields_so_far,
            )  # fmt: skip
            wdeposits[r, (i, j)] = h
        elif kind == SHIFT:
            every = [wide_fields[k] for k in range(steps)]
            h = executor.submit(
                "shift", key, wide_shift, jobf, plan, coarse, i, j, held_first[i, j], *every
            )
            corrected[i, j] = h
            kind_of[id(h)] = "shift"
        else:
            c = plan.colour(i, j)
            around = [
                (final[u] if u in final else loaded(u)) if plan.colour(*u) < c else corrected[u]
                for u in plan.neighbours(i, j)
            ]
            h = executor.submit("legal", key, _legal, jobf, plan, corrected[i, j], *around)
            final[i, j] = h
            kind_of[id(h)] = "legal"
    h = around = parts = results = fields_so_far = every = None  # no longer held here
    weights = {k: w for k, w in _WEIGHTS.items() if wide or k != "shift"}
    total = sum(weights.values()) * max(len(tiles) - len(finished), 1)
    done = 0.0
    counts: dict[tuple[int, int], int] = {}
    tile_of = {id(h): t for t, h in final.items()}
    watched = [*relaxed.values(), *firsts.values()]
    watched += [*(corrected.values() if wide else ()), *final.values()]
    if fields is not None:  # first: in process, handles are handed over in this order
        for name, h in made.items():
            kind_of[id(h)] = name
        watched[:0] = made.values()
    # The graph holds what it still needs: a relaxed, corrected or final tile is dropped
    # here once handed over, and its dots are freed when the last task reading them is
    # done (holding all of them to the end took the monitor panel, 27M dots, to 4 GiB).
    # What the corrected dots are made from stays referenced to the end: a correction
    # lost with a dead worker is made again from it, which Dask would otherwise have
    # forgotten once every correction that read it was done ("cancelled: already
    # forgotten", seen with a frozen worker). Without a wide pass that is the merged dots
    # of nine tiles (and the seam moves); with one, the tile's first pass's positions and
    # the wide field (the merged dots, 32 B a dot, are then let go once every first pass is
    # made: the wide pass holds every tile's first positions, 16 B a dot, across its
    # barrier instead; the full first pass is let go once they and its deposit are made).
    # So do the panel-wide fields and the deposits they were solved from (a few cells a
    # tile): a relaxation or a correction lost with a dead worker needs its field again.
    keep = [*deposits.values(), coarse]
    if wide:
        keep += [*held_first.values(), *wdeposits.values(), *wide_fields.values()]
    else:
        keep += [*merged.values(), *seams.values()]
    initial.clear(), relaxed.clear(), seams.clear(), merged.clear(), corrected.clear()
    deposits.clear(), firsts.clear(), slims.clear(), wdeposits.clear(), wide_fields.clear()
    coarse = None
    final.clear()
    made.clear()
    n_done, n_relaxed = len(finished), 0
    held.clear()
    for h in executor.finished(watched):
        kind = kind_of[id(h)]
        if kind in names:
            value = executor.result(h)
            if value is not None:
                fields.write_extra(kind, value.to_arrays())
            del h, value
            continue
        done += _WEIGHTS[kind] + (_WEIGHTS["seams"] if kind == "relax" else 0.0)
        n_relaxed += kind == "relax"
        if kind == "legal":
            t = tile_of[id(h)]
            fin = executor.result(h)
            sink(t, fin.xy, fin.footprints)
            counts[t] = len(fin.xy)
            n_done += 1
            del fin
        del h
        if progress is not None:
            elapsed = time.perf_counter() - t0
            frac = min(done / total, 1.0)
            eta = elapsed * (1 - frac) / frac if frac > 0 else float("nan")
            progress(
                frac,
                f"tiles: {n_relaxed}/{len(tiles)} relaxed, {n_done}/{len(tiles)} finished, "
                f"ETA {eta:.0f} s",
            )
    keep.clear()
    return TiledRun(plan, counts, time.perf_counter() - t0)


def tiny_job() -> Job:
    """A 2 x 2-tile job of ~1,500 dots that runs every kernel of a tiled run."""
    grid = np.array([[0.2, 0.3], [0.0, 0.35]])
    return Job(6.0, 6.0, DensityMap(grid, 6.0, 6.0), 0.046, OptimizeParams(max_iter=6))


def warm_up() -> int:
    """Compile (and cache) every kernel of a tiled run in this process; returns dots."""
    job = tiny_job()
    out: list[int] = []
    run_tiles(job, plan_tiles(job, side=3.0), InProcess(), lambda t, xy, d: out.append(len(xy)))
    return sum(out)
