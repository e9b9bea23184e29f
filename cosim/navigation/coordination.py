"""Fleet coordination: paths for all robots on a coarse grid, executed through an action dependency graph.

`[fleet] coordination = "mapf" | "prioritized"` (with "none" each robot plans alone and this module
is not used).

**The coordination grid** (`CoordinationGrid`). The map's cells (0.5 m in the warehouse) are much
smaller than a robot (1 m across); a multi-agent path on them would let two robots stand in
neighbouring cells. So the plan uses a coarse grid of square cells of side `size`: the smallest
multiple of the map's resolution that is at least 2 (r + `CLEARANCE`), r the largest robot radius
(2.0 m for r = 0.5 m on a 0.5 m map). A coarse cell is a block of k x k map cells, aligned on the
map's lower-left corner (rows left over at the map's top and columns at its right belong to no
coarse cell); it is free only when all its map cells are free on the known map. The footprint of a
robot at a free cell's centre, grown by the clearance, then lies inside the cell, and a robot moving
between the centres of two neighbouring free cells stays inside their union, even when it cuts a
corner up to the straight line between two centres (the line between the centres of two cells
diagonal to each other stays s / sqrt(2) = 1.41 m > 2 r from the other two cells' centres).

**Plans.** "mapf": `planner.mapf.solve` on that grid (4-connected moves and waits, no two robots in
one cell or swapping cells in one step) from each robot's cell to the cell of its current goal.
"prioritized": the robots one after the other in fleet order, each by a space-time search against
the paths of the ones before (`planner.mapf.single_agent_path`: SIPP; the simple alternative); a
robot that finds no path goes first in the next attempt (at most one attempt per robot). A
goal cell that another robot already rests on or heads for (two robots with the same mission
stop) makes the later robot wait where it is until the next re-solve.

**Execution** (`ActionGraph`, after Hönig et al., "Persistent and robust execution of MAPF schedules
in warehouses", RA-L 2019). A robot's plan becomes a sequence of actions: first "settle" (get
wholly into its start cell), then one move per change of cell (waits are no actions). The move of
robot i into cell c at plan time t depends on i's previous action and on every other robot's move
out of c that the plan has at a time <= t (for each other robot, its latest such move is enough:
its own actions are ordered); any move of another robot into a cell that robot i's footprint
overlaps when the plan is made (besides its start cell) depends on i's settle. These dependencies
follow plan time, so the graph has no cycle: however late a robot is, no one deadlocks, and no
one enters a cell before the robots planned there earlier have left it.

The coordinator releases to each robot the longest run of its next actions whose dependencies on
the other robots are done; the robot's planner component gets the released cells' centres as
waypoints (`PlannerComponent.follow`) and its Pure Pursuit stops at the last one. A move counts
done when the robot's footprint, grown by `LEFT_MARGIN`, no longer overlaps the cell it left and
its centre is in the cell entered or a later released one: leaving is what the next robot waits
for, so this lets it go as early as is safe (the robot released behind it then enters a cell that
the one ahead has wholly left; a robot never needs to stop at a cell's centre when its next
cell is released). Pure Pursuit stops within its goal tolerance of its LAST waypoint; the
coordinator puts that last waypoint the tolerance beyond the last released centre, along the
last move, so the robot stops at the centre itself (at the mission's goal cell: at the point of
the cell's inner square nearest to the goal); the waypoints end before the first reversal or
return to a cell (a path that turns back passes by its end before), the rest follows once the
robot is there. A robot whose path beyond its nearest segment lies behind it (it must turn round)
gets its waypoints from where it stands by a point to its side (`turn_round`): Pure Pursuit with
its lookahead point straight behind does not turn and drove on out of the cell.

**Lifelong re-solves.** When a robot needs its next mission goal, all robots are planned again:
each from the cell of its last released action (where it is committed to go), its remaining goal
as goal (a robot that completed or dwells stays where it is); the new graph starts with every
robot's settle (its footprint cells and released cells protected until it has settled). Unknown
obstacles: the robots' lidars do not see each other (the coordinator keeps them apart), so what a
robot's planner component marks in its costmap (it still takes every scan while it follows) is an
obstacle not on the map; a coarse cell with such a mark on any robot's remaining path (its
lead-in, released and planned cells) is blocked from then on, and all robots are planned again,
around it (a robot already in that cell may leave it). And a robot that has released moves ahead
but has not moved `STUCK_DISTANCE` for `BLOCKED_AFTER` seconds since it had any (something on its
way that VFH could not pass; not a robot halted by `stop`, nor one waiting for a release) has its
next cell closed for the next plan, and all are planned again, that robot from the cell where it
stands (the cells released ahead of it given up: planned from its committed cell, its way there
would still pass the closed cell).

Speed: the MAPF solver is anytime: `MAPF_TIME_LIMIT` s of wall time per solve (small instances
are proven optimal long before, so their plans are the same every run; a large fleet's plan can
depend on how far the improvement got).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

CLEARANCE = 0.5  # [m] between a robot's footprint and its coordination cell's sides (cell >= 2 (r + this))
LEFT_MARGIN = 0.05  # [m] the footprint grown by this is out of a cell: the robot has left it
BLOCKED_AFTER = 10.0  # [s] with released moves and no movement: blocked, re-solve
STUCK_DISTANCE = 0.25  # [m] moved less than this: not moving
RELEASE_AHEAD = 3  # actions released beyond the done ones (a lifelong re-solve can still change the rest)
MAPF_TIME_LIMIT = 0.2  # [s] of wall time per MAPF solve (the first solution takes ~1 ms at 50 robots)
STOP_SHORT = 0.02  # [m] the stop point lies this much before the released end (Pure Pursuit's `<=`)
TURN_OFFSET = 0.3  # [m] a robot that must turn round first heads for a point this far to its side
TURN_NEAR = 0.5  # [m] waypoints this close to a turning robot are passed (it turns where it stands)

Cell = tuple[int, int]


class CoordinationError(Exception):
    """Coordination cannot go on (no plan); the run reports it."""


# -- the coarse grid ---------------------------------------------------------------------------


class CoordinationGrid:
    """The coarse grid of the module docstring over the known map `grid` (a planner.OccupancyGrid)
    for robots of radius up to `radius` [m]. `.grid`: a planner.OccupancyGrid of the coarse cells
    (resolution `.size`, the map's origin)."""

    def __init__(self, grid, radius: float, clearance: float = CLEARANCE) -> None:
        from planner.grid import OccupancyGrid

        resolution = grid.resolution
        self.k = max(1, math.ceil(2.0 * (radius + clearance) / resolution - 1e-9))
        self.size = self.k * resolution
        rows, cols = grid.shape[0] // self.k, grid.shape[1] // self.k
        if rows == 0 or cols == 0:
            raise CoordinationError(
                f"the map ({grid.shape[0]}x{grid.shape[1]} cells) is smaller than one coordination cell "
                f"({self.size:g} m)"
            )
        known = np.asarray(grid.occupied)
        # Map cells touching a known obstacle (8 neighbours): a lidar return off a wall's face can
        # land in the free cell beside it; a mark there is no unknown obstacle.
        padded = np.pad(known, 1)
        self.near_known = np.zeros_like(known)
        for dr in (0, 1, 2):
            for dc in (0, 1, 2):
                self.near_known |= padded[dr : dr + known.shape[0], dc : dc + known.shape[1]]
        fine = known[grid.shape[0] - rows * self.k :, : cols * self.k]
        blocked = fine.reshape(rows, self.k, cols, self.k).any(axis=(1, 3))
        self.grid = OccupancyGrid(blocked, self.size, grid.origin)
        self.origin = grid.origin
        self.rows, self.cols = rows, cols

    def coarse(self, fine: np.ndarray) -> np.ndarray:
        """A bool array of the map's shape (e.g. the lidar's marks) as coarse cells: True where any
        of a coarse cell's map cells is."""
        rows, cols, k = self.rows, self.cols, self.k
        part = fine[fine.shape[0] - rows * k :, : cols * k]
        return part.reshape(rows, k, cols, k).any(axis=(1, 3))

    def cell_of(self, x: float, y: float) -> Cell | None:
        """The cell containing (x, y) [m], or None outside the coarse grid."""
        col = math.floor((x - self.origin[0]) / self.size)
        from_bottom = math.floor((y - self.origin[1]) / self.size)
        row = self.rows - 1 - from_bottom
        if 0 <= row < self.rows and 0 <= col < self.cols:
            return (row, col)
        return None

    def centre(self, cell: Cell) -> tuple[float, float]:
        row, col = cell
        return (
            self.origin[0] + (col + 0.5) * self.size,
            self.origin[1] + (self.rows - 1 - row + 0.5) * self.size,
        )

    def free(self, cell: Cell | None) -> bool:
        return cell is not None and not bool(self.grid.occupied[cell])

    def distance_to_cell(self, x: float, y: float, cell: Cell) -> float:
        """[m] from (x, y) to the cell's square (0 inside)."""
        cx, cy = self.centre(cell)
        half = self.size / 2.0
        dx = max(abs(x - cx) - half, 0.0)
        dy = max(abs(y - cy) - half, 0.0)
        return math.hypot(dx, dy)

    def overlapped(self, x: float, y: float, radius: float) -> set[Cell]:
        """Cells whose square a disc of `radius` [m] at (x, y) overlaps."""
        cells = set()
        reach = math.ceil(radius / self.size) + 1
        centre = self.cell_of(x, y)
        if centre is None:
            return cells
        row, col = centre
        for r in range(max(0, row - reach), min(self.rows, row + reach + 1)):
            for c in range(max(0, col - reach), min(self.cols, col + reach + 1)):
                if self.distance_to_cell(x, y, (r, c)) < radius:
                    cells.add((r, c))
        return cells

    def inner_point(self, cell: Cell, x: float, y: float, radius: float) -> tuple[float, float]:
        """The point of the cell's inner square (where a footprint of `radius` grown by the margin
        stays inside the cell) nearest to (x, y)."""
        cx, cy = self.centre(cell)
        half = max(self.size / 2.0 - radius - LEFT_MARGIN, 0.0)
        return (min(max(x, cx - half), cx + half), min(max(y, cy - half), cy + half))


# -- the action dependency graph ------------------------------------------------------------------


@dataclass
class Action:
    """One action of one robot: from cell `source` into `target`, arriving at plan time `time`.
    The settle action (index 0) has source == target (the start cell) and time 0. `needs`: the
    (robot, action index) of other robots that must be done first."""

    source: Cell
    target: Cell
    time: int
    needs: list[tuple[int, int]] = field(default_factory=list)

    @property
    def settle(self) -> bool:
        return self.source == self.target


class ActionGraph:
    """The action dependency graph of timed paths (module docstring).

    paths: per robot, its cells per plan time step ((T + 1) x 2, row and column; robots may have
    different lengths: each rests on its last cell afterwards). held: per robot, the cells it may
    overlap when the plan starts besides its start cell (its footprint, the cells it was released
    before): another robot's move into one of them waits for this robot's settle.

    `done[i]` counts robot i's actions done (in order); `released[i]` counts its actions released
    (done ones included). `release()` extends every robot's released run as far as the
    dependencies allow, up to `horizon` actions beyond the done ones (None: no limit); `finish(i)`
    marks robot i's next action done (it must be released).
    """

    def __init__(self, paths, held=None, lead_in=None, horizon: int | None = None) -> None:
        self.horizon = horizon
        paths = [np.asarray(path, dtype=np.int64).reshape(-1, 2) for path in paths]
        held = [set() for _ in paths] if held is None else [set(map(tuple, cells)) for cells in held]
        for cells, path in zip(held, paths, strict=True):
            cells.discard((int(path[0, 0]), int(path[0, 1])))
        self.actions: list[list[Action]] = []
        for path in paths:
            start = (int(path[0, 0]), int(path[0, 1]))
            actions = [Action(start, start, 0)]
            for t in range(1, len(path)):
                source = (int(path[t - 1, 0]), int(path[t - 1, 1]))
                target = (int(path[t, 0]), int(path[t, 1]))
                if source != target:
                    actions.append(Action(source, target, t))
            self.actions.append(actions)
        n = len(paths)
        # Moves out of each cell, per robot: (time, action index), in time order.
        leaving: dict[Cell, list[list[tuple[int, int]]]] = {}
        for i, actions in enumerate(self.actions):
            for k, action in enumerate(actions[1:], start=1):
                leaving.setdefault(action.source, [[] for _ in range(n)])[i].append((action.time, k))
        self.held = held
        # Per robot, the cells it drives through to its start cell (released before a re-solve).
        self.lead_in = [list(cells) for cells in lead_in] if lead_in is not None else [[] for _ in paths]
        starts = [actions[0].target for actions in self.actions]
        for i, actions in enumerate(self.actions):
            for action in actions:
                by_robot = leaving.get(action.target)
                for j in range(n):
                    if j == i:
                        continue
                    if action.settle:
                        # Its start cell in another robot's footprint: wait for that one to settle
                        # (both in each other's: the lower index settles first).
                        if starts[i] in held[j] and (j < i or starts[j] not in held[i]):
                            action.needs.append((j, 0))
                        continue
                    moves_out = by_robot[j] if by_robot is not None else ()
                    before = [index for time, index in moves_out if time <= action.time]
                    if before:
                        action.needs.append((j, before[-1]))
                    if action.target in held[j]:
                        action.needs.append((j, 0))
        self.done = [0] * n
        self.released = [0] * n
        self.release()

    def __len__(self) -> int:
        return len(self.actions)

    def ready(self, i: int, k: int) -> bool:
        """Whether every other robot's action that robot i's action k needs is done."""
        return all(self.done[j] > index for j, index in self.actions[i][k].needs)

    def release(self) -> list[int]:
        """Extend the released runs; returns the robots whose run grew."""
        grown = []
        for i, actions in enumerate(self.actions):
            k = self.released[i]
            end = len(actions) if self.horizon is None else min(len(actions), self.done[i] + self.horizon)
            while k < end and self.ready(i, k):
                k += 1
            if k != self.released[i]:
                self.released[i] = k
                grown.append(i)
        return grown

    def finish(self, i: int) -> None:
        if self.done[i] >= self.released[i]:
            raise ValueError(f"robot {i}'s next action is not released")
        self.done[i] += 1

    def next_action(self, i: int) -> Action | None:
        """Robot i's first action not done, or None."""
        return self.actions[i][self.done[i]] if self.done[i] < len(self.actions[i]) else None

    def committed(self, i: int) -> Cell:
        """The target of robot i's last released action (its start cell if none is)."""
        return self.actions[i][max(self.released[i], 1) - 1].target

    def pending(self, i: int) -> list[Cell]:
        """Targets of robot i's released actions not done yet, in order."""
        return [action.target for action in self.actions[i][self.done[i] : self.released[i]]]

    @property
    def complete(self) -> bool:
        return all(d == len(actions) for d, actions in zip(self.done, self.actions, strict=True))

    def check_acyclic(self) -> None:
        """Raise ValueError if the dependencies have a cycle (they cannot: they follow plan time)."""
        state: dict[tuple[int, int], int] = {}
        for i, actions in enumerate(self.actions):
            for k in range(len(actions)):
                stack = [((i, k), iter(self._edges(i, k)))]
                if state.get((i, k)) == 2:
                    continue
                state[(i, k)] = 1
                while stack:
                    node, edges = stack[-1]
                    nxt = next(edges, None)
                    if nxt is None:
                        state[node] = 2
                        stack.pop()
                    elif state.get(nxt) == 1:
                        raise ValueError(f"dependency cycle through robot {nxt[0]} action {nxt[1]}")
                    elif state.get(nxt) is None:
                        state[nxt] = 1
                        stack.append((nxt, iter(self._edges(*nxt))))

    def _edges(self, i: int, k: int):
        yield from self.actions[i][k].needs
        if k > 0:
            yield (i, k - 1)


# -- planning ------------------------------------------------------------------------------------


def plan_paths(method: str, grid, starts: list[Cell], goals: list[Cell], time_limit: float = MAPF_TIME_LIMIT):
    """Paths (one (T + 1) x 2 array per robot) from `starts` to `goals` on the coarse `grid`
    (planner.OccupancyGrid) by `method` ("mapf" or "prioritized"); None when there is none."""
    paths = _plan(method, grid, starts, goals, time_limit)
    return paths if paths is not None and valid_paths(paths, starts, goals) else None


def valid_paths(paths, starts, goals) -> bool:
    """Whether `paths` go from `starts` to `goals` by 4-connected moves and waits with no two robots
    in one cell nor swapping cells at any time step (each rests on its last cell afterwards)."""
    if len(paths) != len(starts):
        return False
    length = max(len(path) for path in paths)
    padded = []
    for path, start, goal in zip(paths, starts, goals, strict=True):
        path = np.asarray(path, dtype=np.int64).reshape(-1, 2)
        if tuple(path[0]) != tuple(start) or tuple(path[-1]) != tuple(goal):
            return False
        if len(path) > 1 and np.abs(np.diff(path, axis=0)).sum(axis=1).max() > 1:
            return False
        padded.append(np.vstack([path, np.repeat(path[-1:], length - len(path), axis=0)]))
    cells = np.stack(padded)  # robots x time x 2
    for t in range(length):
        here = [tuple(cell) for cell in cells[:, t]]
        if len(set(here)) != len(here):
            return False
        if t > 0:
            moves = {
                (tuple(a), tuple(b))
                for a, b in zip(cells[:, t - 1], cells[:, t], strict=True)
                if tuple(a) != tuple(b)
            }
            if any((b, a) in moves for a, b in moves):
                return False
    return True


def _plan(method: str, grid, starts, goals, time_limit: float):
    from planner import mapf
    from planner.errors import PlannerError

    if method == "mapf":
        try:
            result = mapf.solve(grid, starts, goals, time_limit=time_limit)
        except PlannerError:
            return None
        return [np.asarray(path, dtype=np.int64) for path in result.paths] if result.solved else None
    # Prioritized: in priority order, each robot by SIPP against the paths of the ones before. A
    # robot that finds no path (one planned before it runs over its start, or rests in its way)
    # goes first in the next attempt; at most one attempt per robot.
    n = len(starts)
    order = list(range(n))
    for _ in range(n):
        paths: list[np.ndarray] = []
        failed = None
        for i in order:
            try:
                path = mapf.single_agent_path(grid, paths, starts[i], goals[i])
            except PlannerError:
                return None
            if path is None:
                failed = i
                break
            paths.append(np.asarray(path, dtype=np.int64))
        if failed is None:
            by_robot = [None] * n
            for i, path in zip(order, paths, strict=True):
                by_robot[i] = path
            return by_robot
        if order[0] == failed:
            return None
        order.remove(failed)
        order.insert(0, failed)
    return None


# -- the coordinator -------------------------------------------------------------------------------


@dataclass
class Agent:
    """What the coordinator knows of one robot: radius [m], Pure Pursuit's goal tolerance [m]."""

    name: str
    radius: float
    tolerance: float
    goal: tuple[float, float] | None = None  # [m] current goal; None: stay (completed, dwelling)
    waiting: bool = False  # its goal cell was taken: it waits where it is
    assigned: Cell | None = None  # the goal cell it heads for in the current plan (not waiting)
    shown: np.ndarray | None = None  # the waypoints it follows
    moved_at: float = 0.0  # [s] last time it moved STUCK_DISTANCE
    moved_from: tuple[float, float] = (math.nan, math.nan)


class Coordinator:
    """Plans and releases cells for every robot of a fleet (module docstring).

    `Coordinator(method, grid, agents)` with the fleet's known map; `start(poses, goals)` plans for
    the first time (CoordinationError: a start or goal cell is blocked, two robots in one cell, or
    no plan); then, before each block, `update(t, poses)` marks actions done, releases, re-solves
    when asked (`new_goal`) or when a robot is blocked, and returns per robot the waypoints to
    follow when they changed (else None).
    """

    def __init__(self, method: str, grid, agents: list[Agent], clearance: float = CLEARANCE) -> None:
        self.method = method
        self.cells = CoordinationGrid(grid, max(agent.radius for agent in agents), clearance)
        self.agents = agents
        self.graph: ActionGraph | None = None
        self.blocked: set[Cell] = set()  # cells with unknown obstacles (for good)
        self.avoid: set[Cell] = set()  # cells a stuck robot could not enter (for the next plan)
        self.stuck: set[int] = set()  # robots planned again from where they stand (next plan)
        self.solves = 0
        self.solve_time = 0.0  # [s] of wall time planning
        self.failures = 0  # solves that found no plan (the robots go on with the last one)
        self.failed_at: float | None = None
        self._resolve = False
        self.halted: set[int] = set()

    # Cells and checks

    def goal_cell(self, x: float, y: float) -> Cell | None:
        return self.cells.cell_of(x, y)

    def check(self, poses, goals_of) -> None:
        """One-line errors for starts and goals the coarse grid cannot take."""
        seen: dict[Cell, str] = {}
        for agent, pose in zip(self.agents, poses, strict=True):
            cell = self.cells.cell_of(pose[0], pose[1])
            if not self.cells.free(cell):
                raise CoordinationError(
                    f"{agent.name} starts at ({pose[0]:g}, {pose[1]:g}) m in a coordination cell "
                    f"({self.cells.size:g} m) that is not free: a wall or rack lies in it"
                )
            if cell in seen:
                raise CoordinationError(
                    f"{agent.name} and {seen[cell]} start in one coordination cell {cell} "
                    f"({self.cells.size:g} m): start them further apart"
                )
            seen[cell] = agent.name
        last: dict[Cell, str] = {}
        for agent, goals in zip(self.agents, goals_of, strict=True):
            cell = self.cells.cell_of(*goals[-1])
            if cell in last:
                raise CoordinationError(
                    f"{agent.name} and {last[cell]} end in one coordination cell {cell} "
                    f"({self.cells.size:g} m): the first to arrive would stay there for good"
                )
            last[cell] = agent.name
            for x, y in goals:
                if not self.cells.free(self.cells.cell_of(x, y)):
                    raise CoordinationError(
                        f"{agent.name}'s goal ({x:g}, {y:g}) m lies in a coordination cell "
                        f"({self.cells.size:g} m) that is not free: a wall or rack lies in it"
                    )

    # Planning

    def start(self, t: float, poses) -> None:
        for agent, pose in zip(self.agents, poses, strict=True):
            agent.moved_at, agent.moved_from = t, (float(pose[0]), float(pose[1]))
        if not self._solve(t, poses):
            raise CoordinationError(f"'{self.method}' found no plan for the robots' starts and goals")

    def new_goal(self, i: int, goal: tuple[float, float] | None) -> None:
        """Robot i's current goal changed (None: it stays where it is); re-solve before the next block."""
        self.agents[i].goal = goal
        self._resolve = True

    def _solve(self, t: float, poses) -> bool:
        import time

        n = len(self.agents)
        starts, held, lead_in = [], [], []
        for i in range(n):
            x, y = float(poses[i][0]), float(poses[i][1])
            if self.graph is None or i in self.stuck:
                # A stuck robot gives up the cells released ahead of it (the one it could not
                # enter among them) and is planned from where it stands: from its committed cell
                # its lead-in would still pass the closed cell.
                start = self.cells.cell_of(x, y)
                pending: list[Cell] = []
                if self.graph is not None:
                    lead_in.append([])
            else:
                start = self.graph.committed(i)
                pending = self.graph.pending(i)
                step = self.graph.next_action(i)
                way = self.graph.lead_in[i] if step is not None and step.settle else []
                way = [*way, step.source] if step is not None else way
                way = [*way, *pending]
                way = way[: way.index(start)] if start in way else way  # the shortest part to the start
                here = self.cells.cell_of(x, y)
                if here in way:  # the cells behind the robot are passed
                    way = way[len(way) - 1 - way[::-1].index(here) :]
                lead_in.append(way)
            starts.append(start)
            cells = self.cells.overlapped(x, y, self.agents[i].radius + LEFT_MARGIN) | set(pending)
            cells |= set(lead_in[i]) if lead_in else set()
            held.append(cells - {start})
        goals: list[Cell] = [None] * n  # type: ignore[list-item]
        taken: set[Cell] = set()
        # Resting robots first, then the robots already heading for their goal cell (assigned it in
        # the last plan): a robot that asks for that cell later waits, it does not take the cell
        # from one on its way (by fleet order the last robots waited at their shelves for 400 s,
        # the cell passing to each robot with a lower index that came to need it meanwhile).
        wanted = [None if agent.goal is None else self.cells.cell_of(*agent.goal) for agent in self.agents]

        def rank(i: int) -> int:
            agent = self.agents[i]
            if agent.goal is None:
                return 0
            return 1 if agent.assigned is not None and agent.assigned == wanted[i] else 2

        order = sorted(range(n), key=rank)
        for i in order:
            agent = self.agents[i]
            cell = starts[i] if agent.goal is None else wanted[i]
            agent.waiting = False
            if cell in taken or not self.cells.free(cell) or (cell in self.blocked and cell != starts[i]):
                # Its goal is another's or blocked: it waits where it is, or, if another robot
                # needs that cell as its goal, at the nearest cell no one needs.
                cell, agent.waiting = self._nearest_untaken(starts[i], taken), True
            goals[i] = cell
            taken.add(cell)
        for i, agent in enumerate(self.agents):
            agent.assigned = None if agent.waiting or agent.goal is None else goals[i]
        grid = self.cells.grid
        closed = (self.blocked | self.avoid) - set(starts) - set(goals)
        self.avoid, self.stuck = set(), set()
        if closed:
            from planner.grid import OccupancyGrid

            occupied = grid.occupied.copy()
            for cell in closed:
                occupied[cell] = True
            grid = OccupancyGrid(occupied, grid.resolution, grid.origin)
        began = time.perf_counter()
        paths = plan_paths(self.method, grid, starts, goals) if len(set(goals)) == n else None
        self.solve_time += time.perf_counter() - began
        self.solves += 1
        if paths is None:
            self.failed_at, self._resolve = t, False  # tried again a second later
            self.failures += 1
            return False
        self.failed_at = None
        self.graph = ActionGraph(paths, held, lead_in or None, RELEASE_AHEAD)
        for agent in self.agents:
            agent.shown = None
        self._resolve = False
        return True

    def _nearest_untaken(self, start: Cell, taken: set[Cell]) -> Cell:
        """The free cell nearest to `start` (4-connected steps) not in `taken` nor blocked."""
        from collections import deque

        occupied = self.cells.grid.occupied
        seen, queue = {start}, deque([start])
        while queue:
            cell = queue.popleft()
            if cell not in taken and (cell not in self.blocked or cell == start):
                return cell
            row, col = cell
            for nxt in ((row - 1, col), (row + 1, col), (row, col - 1), (row, col + 1)):
                if (
                    0 <= nxt[0] < self.cells.rows
                    and 0 <= nxt[1] < self.cells.cols
                    and not occupied[nxt]
                    and nxt not in self.blocked
                    and nxt not in seen
                ):
                    seen.add(nxt)
                    queue.append(nxt)
        return start

    # Execution

    def update(self, t: float, poses, marks=None) -> dict[int, np.ndarray]:
        """Before the block from t [s]: done actions, re-solves, releases; the robots whose
        waypoints changed and their new waypoints (N x 2 [m]). `marks`: per robot, the map cells its
        lidar has seen occupied beyond the known map (or None): a coarse cell with a mark on a
        robot's remaining path is blocked, and all are planned again."""
        graph = self.graph
        if marks is not None:
            self._see(marks)
        for i, agent in enumerate(self.agents):
            x, y = float(poses[i][0]), float(poses[i][1])
            self._advance(i, x, y)
            if (
                i in self.halted
                or graph.done[i] >= graph.released[i]  # nothing released: waiting is not being stuck
                or math.hypot(x - agent.moved_from[0], y - agent.moved_from[1]) >= STUCK_DISTANCE
            ):
                agent.moved_at, agent.moved_from = t, (x, y)
            elif graph.done[i] < graph.released[i] and t - agent.moved_at >= BLOCKED_AFTER:
                nxt = graph.next_action(i)
                if nxt is not None and not nxt.settle:
                    self.avoid.add(nxt.target)  # for the next plan only: no obstacle was seen
                    self.stuck.add(i)
                    self._resolve = True
                agent.moved_at = t
        if self._resolve or (self.failed_at is not None and t - self.failed_at >= 1.0):
            if self._solve(t, poses):
                for i in range(len(self.agents)):
                    self._advance(i, float(poses[i][0]), float(poses[i][1]))
        changed = {}
        for i, agent in enumerate(self.agents):
            if i in self.halted:
                continue
            waypoints = self.waypoints(i, poses[i])
            # The same cells: the same waypoints (the end's extension keeps the first direction).
            if agent.shown is None or not np.array_equal(waypoints[:-1], agent.shown[:-1]):
                agent.shown = waypoints
                changed[i] = turn_round(poses[i], waypoints)
        return changed

    def _see(self, marks) -> None:
        """Block the coarse cells with unknown obstacles that lie on a robot's remaining path."""
        seen = None
        for fine in marks:
            if fine is not None and fine.any():
                coarse = self.cells.coarse(fine & ~self.cells.near_known)
                seen = coarse if seen is None else seen | coarse
        if seen is None:
            return
        graph = self.graph
        for i, actions in enumerate(graph.actions):
            ahead = {action.target for action in actions[graph.done[i] :]} | set(graph.lead_in[i])
            new = {cell for cell in ahead if seen[cell]} - self.blocked
            if new:
                self.blocked |= new
                self._resolve = True

    def _advance(self, i: int, x: float, y: float) -> None:
        """Mark robot i's released actions done while their condition holds; release."""
        graph = self.graph
        radius = self.agents[i].radius + LEFT_MARGIN
        while graph.done[i] < graph.released[i]:
            action = graph.actions[i][graph.done[i]]
            ahead = {a.target for a in graph.actions[i][graph.done[i] : graph.released[i]]}
            left = graph.held[i] if action.settle else (action.source,)
            ok = self.cells.cell_of(x, y) in ahead and all(
                self.cells.distance_to_cell(x, y, cell) >= radius for cell in left
            )
            if not ok:
                break
            graph.finish(i)
            graph.release()

    def waypoints(self, i: int, pose) -> np.ndarray:
        """The released cells ahead of robot i as Pure Pursuit waypoints (module docstring)."""
        graph = self.graph
        agent = self.agents[i]
        actions = graph.actions[i]
        first = graph.done[i]
        last = graph.released[i]
        cells = list(graph.lead_in[i]) if first == 0 else []
        cells += [actions[first].source] if first < len(actions) else []
        cells += [action.target for action in actions[first:last]]
        if not cells:
            cells = [graph.committed(i)]
        unique = [cells[0]]
        unique += [cell for previous, cell in zip(cells, cells[1:], strict=False) if cell != previous]
        points = [self.cells.centre(cell) for cell in unique]
        final = unique[-1]
        if agent.goal is not None and not agent.waiting and last == len(actions):
            if self.cells.cell_of(*agent.goal) == final:
                points[-1] = self.cells.inner_point(final, agent.goal[0], agent.goal[1], agent.radius)
        # Up to the first reversal: Pure Pursuit stops near its last waypoint wherever it is on
        # the path, and a path that turns back passes by its end before (the rest comes once the
        # robot is there and the move into that cell is done).
        for j in range(2, len(points)):
            ahead = np.subtract(points[j], points[j - 1])
            behind = np.subtract(points[j - 1], points[j - 2])
            if float(np.dot(ahead, behind)) < 0.0 or points[j] in points[: j - 1]:
                points = points[:j]
                break
        end = np.array(points[-1])
        # The direction of arrival: along the last move, or from the robot when there is none.
        here = np.array([float(pose[0]), float(pose[1])])
        direction = end - (np.array(points[-2]) if len(points) >= 2 else here)
        if np.hypot(*direction) < 0.1:
            direction = np.array([math.cos(float(pose[2])), math.sin(float(pose[2]))])
        direction = direction / max(float(np.hypot(*direction)), 1e-12)
        beyond = end + max(agent.tolerance - STOP_SHORT, 0.0) * direction
        return np.array([*points, beyond], dtype=float)


def turn_round(pose, waypoints: np.ndarray) -> np.ndarray:
    """`waypoints` for a robot at `pose` (x, y, theta) that must turn round first: starting at the
    robot, by a point `TURN_OFFSET` to its side (the side the path lies on), then on from the first
    waypoint more than `TURN_NEAR` away after the path's segment nearest to the robot. Pure
    Pursuit turns a robot by 2 v sin(alpha) / L toward its lookahead point at angle alpha: a
    lookahead point (nearly) straight behind gives sin(alpha) ~ 0, and the robot drove on straight
    ahead for more than 1 m (out of its cell into the next robot's) before it turned. From the side
    point alpha starts near 90 degrees: the robot turns at once, within about TURN_OFFSET of where
    it stands. Waypoints ahead of the robot (less than 120 degrees off its heading) are returned as
    they are."""
    x, y, theta = float(pose[0]), float(pose[1]), float(pose[2])
    here = np.array([x, y])
    if len(waypoints) < 2:
        return waypoints
    # The robot's place on the path: the segment nearest to it (the waypoints can begin with cells
    # it has passed); the way on is the first waypoint after that segment's start beyond TURN_NEAR.
    starts, ends = waypoints[:-1], waypoints[1:]
    along = ends - starts
    length2 = np.maximum((along * along).sum(axis=1), 1e-12)
    s = np.clip(((here - starts) * along).sum(axis=1) / length2, 0.0, 1.0)
    nearest = int(np.argmin(np.hypot(*(starts + s[:, None] * along - here).T)))
    far = np.hypot(*(waypoints - here).T) > TURN_NEAR
    far[: nearest + 1] = False
    if not far.any():
        return waypoints
    first = int(np.argmax(far))
    way = waypoints[first] - here
    heading = np.array([math.cos(theta), math.sin(theta)])
    if float(np.dot(way, heading)) >= -0.5 * float(np.hypot(*way)):
        return waypoints
    side = 1.0 if heading[0] * way[1] - heading[1] * way[0] >= 0.0 else -1.0
    normal = side * np.array([-heading[1], heading[0]])
    return np.array([here, here + TURN_OFFSET * normal, *waypoints[first:]], dtype=float)


# -- the fleet run's hook --------------------------------------------------------------------------


class FleetCoordination:
    """What `cosim.navigation.fleet` calls before every block: the coordinator (with
    `coordination` other than "none") and the robots' `stop`s. `make(fleet, robots)` returns None
    when there is neither (the run is exactly the uncoordinated one). `before_block(t)` with the
    robots' poses at t [s] hands each robot's planner component its waypoints when they change.

    A stop `{ at, duration }` halts the robot from the first block starting at or after `at` for
    `duration` (to block boundaries, 0.1 s with the template's lidar): its planner gets its
    position as the only waypoint, so Pure Pursuit reports the goal reached and the mixer stops it;
    then it drives on (coordinated: along its released cells; alone: its own plan, replanning).
    """

    def __init__(self, fleet, robots, coordinator: Coordinator | None) -> None:
        self.robots = robots
        self.coordinator = coordinator
        self.halted: set[int] = set()
        self.stops = {k: each.robot.stop for k, each in enumerate(robots) if each.robot.stop is not None}

    @classmethod
    def make(cls, fleet, robots) -> FleetCoordination | None:
        """The hook for `fleet`, or None; `CosimError` (one line) for starts or goals the
        coordination grid cannot take."""
        from cosim.errors import CosimError

        method = fleet.settings.coordination
        coordinator = None
        if method != "none":
            agents = []
            for each in robots:
                parameters = each.built.parameters.get("pure_pursuit", {})
                tolerance = float(parameters.get("goal_tolerance", each.robot.scenario.goal_tolerance))
                agents.append(Agent(each.robot.name, each.robot.radius, tolerance))
            try:
                coordinator = Coordinator(method, robots[0].built.grid, agents)
                poses = [each.robot.scenario.start for each in robots]
                coordinator.check(poses, [[(g.x, g.y) for g in each.robot.mission] for each in robots])
                for agent, each in zip(agents, robots, strict=True):
                    agent.goal = (each.goals[0].x, each.goals[0].y)
                coordinator.start(0.0, poses)
            except CoordinationError as error:
                raise CosimError(f"{fleet.source}: [fleet] coordination = '{method}': {error}") from None
        if coordinator is None and not any(each.robot.stop is not None for each in robots):
            return None
        return cls(fleet, robots, coordinator)

    def _pose(self, each) -> tuple[float, float, float]:
        if len(each.poses):
            return tuple(float(v) for v in each.poses[-1])
        return each.pose

    def before_block(self, t: float) -> None:
        poses = [self._pose(each) for each in self.robots]
        coordinator = self.coordinator
        for k, (at, duration) in self.stops.items():
            planner = self.robots[k].built.planner
            halt = at - 1e-9 <= t < at + duration - 1e-9 and self.robots[k].judged
            if halt and k not in self.halted:
                self.halted.add(k)
                planner.follow(np.array([poses[k][:2]]), t)
            elif not halt and k in self.halted:
                self.halted.discard(k)
                if coordinator is None:
                    planner.follow(None, t)
                else:
                    coordinator.agents[k].shown = None  # send its released cells again
        if coordinator is None:
            return
        coordinator.halted = self.halted
        for k, each in enumerate(self.robots):
            wanted = None
            if each.judged and each.dwell_until is None and not each.pending_goal:
                goal = each.goals[each.goal_index]
                wanted = (goal.x, goal.y)
            if wanted != coordinator.agents[k].goal:
                coordinator.new_goal(k, wanted)
        marks = [
            each.built.planner.costmap.marked if each.built.planner.replanning is not None else None
            for each in self.robots
        ]
        for k, waypoints in coordinator.update(t, poses, marks).items():
            if k not in self.halted:
                self.robots[k].built.planner.follow(waypoints, t)
