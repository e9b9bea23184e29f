"""`cosim plan mapf MAP --scen FILE --agents N`: a Moving AI MAPF instance solved by planner.mapf.

The first N agents of the `.scen` file (start and goal cells) on MAP's free cells, 4-connected moves
and waits; prints whether it was solved and why the solver stopped, the sum of costs over the lower
bound (the sum of the agents' own shortest distances), the makespan, the time to the first solution
and the total time [s]. `--png OUT` draws the map and every agent's path (one colour per agent, its
start a dot, its goal a square). Exit 0 when solved, 1 when not, 2 for bad input.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from cosim.errors import CosimError

DPI = 100
FIGURE_PX = (1000, 700)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scen", type=Path, metavar="FILE", help="mapf: Moving AI .scen file of the agents")
    parser.add_argument("--agents", type=int, metavar="N", help="mapf: the first N agents of --scen")
    parser.add_argument(
        "--time-limit", type=float, default=10.0, metavar="S", help="mapf: wall time [s] (10)"
    )
    parser.add_argument("--seed", type=int, default=0, metavar="K", help="mapf: random seed (0)")


def run(args: argparse.Namespace, map_path: Path) -> int:
    import planner
    from planner.mapf import solve
    from planner.mapf_scen import read_scen

    if args.scen is None or args.agents is None:
        raise CosimError("cosim plan mapf needs --scen FILE and --agents N")
    if not map_path.is_file():
        raise CosimError(f"{map_path}: map not found")
    if not args.scen.is_file():
        raise CosimError(f"{args.scen}: scenario not found")
    grid = planner.OccupancyGrid.from_file(map_path)
    starts, goals = read_scen(args.scen, args.agents)
    result = solve(grid, starts, goals, time_limit=args.time_limit, seed=args.seed)
    rows, cols = grid.shape
    print(f"{map_path.name} ({rows} x {cols} cells), {args.scen.name}: {len(starts)} agents")
    print(f"solved          {'yes' if result.solved else 'no'} ({result.status})")
    if result.solved:
        ratio = result.sum_of_costs / result.lower_bound if result.lower_bound else 1.0
        print(f"sum of costs    {result.sum_of_costs} / lower bound {result.lower_bound} = {ratio:.3f}")
        print(f"makespan        {result.makespan}")
        print(f"first solution  {result.first_solution:.3f} s")
    else:
        print(f"lower bound     {result.lower_bound}")
    print(f"total time      {result.elapsed:.3f} s (limit {args.time_limit:g} s)")
    print(f"search          {result.nodes} LaCAM nodes, {result.neighbourhoods} neighbourhoods replanned")
    if args.png is not None and result.solved:
        save_paths_png(args.png, grid, result, title=f"{map_path.name}: {len(starts)} agents")
        print(f"wrote {args.png}")
    return 0 if result.solved else 1


def save_paths_png(path: Path, grid, result, title: str = "") -> Path:
    """The map and every agent's path in cells (column right, row down), into a PNG of FIGURE_PX."""
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    rows, cols = grid.shape
    figure, axes = plt.subplots(
        figsize=(FIGURE_PX[0] / DPI, FIGURE_PX[1] / DPI), dpi=DPI, layout="constrained"
    )
    try:
        axes.imshow(
            grid.occupied,
            cmap="Greys",
            vmin=0,
            vmax=1.4,
            extent=(-0.5, cols - 0.5, rows - 0.5, -0.5),
            interpolation="nearest",
        )
        colours = plt.get_cmap("hsv")(np.linspace(0.0, 1.0, len(result.paths), endpoint=False))
        width = 1.2 if len(result.paths) <= 50 else 0.6
        for colour, agent_path in zip(colours, result.paths, strict=True):
            axes.plot(agent_path[:, 1], agent_path[:, 0], color=colour, linewidth=width, alpha=0.85)
            axes.plot(
                agent_path[0, 1],
                agent_path[0, 0],
                "o",
                color=colour,
                markersize=3.5,
                markeredgecolor="k",
                markeredgewidth=0.4,
            )
            axes.plot(
                agent_path[-1, 1],
                agent_path[-1, 0],
                "s",
                color=colour,
                markersize=3.5,
                markeredgecolor="k",
                markeredgewidth=0.4,
            )
        ratio = result.sum_of_costs / result.lower_bound if result.lower_bound else 1.0
        axes.set_title(
            f"{title}\nsum of costs {result.sum_of_costs} ({ratio:.3f} x lower bound), makespan "
            f"{result.makespan}; dot = start, square = goal",
            fontsize=10,
        )
        axes.set_xlabel("column")
        axes.set_ylabel("row")
        axes.set_xlim(-0.5, cols - 0.5)
        axes.set_ylim(rows - 0.5, -0.5)
        axes.set_aspect("equal")
        try:
            figure.savefig(path, dpi=DPI)
        except OSError as error:
            raise CosimError(f"cannot write {path}: {error.strerror or error}") from None
    finally:
        plt.close(figure)
    return path
