"""The planner scenes of the paper's Table II: the GMM gradient-field planner against A*.

For each scene a simulated robot drives the scene's mapping route with a LiDAR; the normal
pipeline (submaps, model selection, global map) turns its scans into a GMM map. The baseline,
a stand-in for ROS move_base's global planner, runs A* on an occupancy grid of the *same*
scans (5 cm cells, obstacles inflated by the robot radius plus one cell, 8-connected, then
shortcut by line of sight). Both plan from the scene's start to its goal; the paths are scored
against the true geometry: length, success, minimum clearance (a collision is clearance under
the robot radius) and planning time per step (for A*, one full plan: what replanning at
every step costs).
"""

from __future__ import annotations

import heapq
import itertools
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from gmmap.errors import InvalidInputError
from gmmap.io.sim.world import World
from gmmap.mapping.globalmap import build_global_map
from gmmap.mapping.planner import OccupancyField, PlannerOptions, PlanResult, plan
from gmmap.mapping.submap import BuildOptions, build_submaps
from gmmap.math.gmm import Gmm

SCENES = ("corner", "passage", "clutter", "front-obstacle")
Progress = Callable[[str], None]


@dataclass
class SceneMap:
    """A scene mapped by one robot: the GMM map and the scans' points, both in the world frame
    (the robot's perfect odometry makes its map frame a known offset of the world's)."""

    gmm: Gmm
    points: np.ndarray
    submaps: int


def map_scene(
    world: World, frames_per_submap: int = 20, seed: int = 0, n_components: int = 200
) -> SceneMap:
    """Drives the scene's route with the default LiDAR and builds the GMM map: full
    covariances and 200 components per submap (a LiDAR submap spans a whole room; with 100,
    one Gaussian per box covers the gap beside it, and wall ends come out short)."""
    from gmmap.io.sim import Lidar, simulate

    (robot,) = simulate(world, robots=1, seed=seed, sensor=Lidar())
    frames = list(robot)
    options = BuildOptions(n_components=n_components, seed=seed).by_frames(frames_per_submap)
    submaps = list(build_submaps(frames, robot.name, options))
    poses = {(s.robot, s.seq): s.anchor for s in submaps}
    gmm = build_global_map(submaps, poses, robot.name).gmm.transform(robot.map_to_world)
    points = np.concatenate(
        [f.points @ f.gt_pose[:3, :3].T + f.gt_pose[:3, 3] for f in frames if len(f.points)]
    )
    return SceneMap(gmm, points, len(submaps))


@dataclass
class Grid:
    """A boolean occupancy grid over the plane: ``blocked[i, j]`` is cell (x, y) =
    origin + (i + 0.5, j + 0.5) * resolution."""

    blocked: np.ndarray
    origin: np.ndarray
    resolution: float

    def cell(self, xy: Sequence[float]) -> tuple[int, int]:
        i, j = np.floor((np.asarray(xy) - self.origin) / self.resolution).astype(int)
        return int(i), int(j)

    def centre(self, cell: tuple[int, int]) -> np.ndarray:
        return self.origin + (np.asarray(cell) + 0.5) * self.resolution

    def free(self, cell: tuple[int, int]) -> bool:
        i, j = cell
        inside = 0 <= i < self.blocked.shape[0] and 0 <= j < self.blocked.shape[1]
        return inside and not self.blocked[i, j]


def occupancy_grid(
    points: np.ndarray,
    radius: float,
    z_band: tuple[float, float],
    resolution: float = 0.05,
    margin: float | None = None,
) -> Grid:
    """Cells holding a point of the height band, inflated by ``radius + margin`` (default
    margin: one cell, so a path along the inflated edge still clears the robot radius)."""
    pts = points[(points[:, 2] >= z_band[0]) & (points[:, 2] <= z_band[1]), :2]
    if not len(pts):
        raise InvalidInputError("no points in the robot's height band: nothing to plan around")
    margin = resolution if margin is None else margin
    origin = pts.min(axis=0) - radius - 2 * resolution
    shape = np.ceil((pts.max(axis=0) + radius + 2 * resolution - origin) / resolution)
    occupied = np.zeros(shape.astype(int), bool)
    idx = np.floor((pts - origin) / resolution).astype(int)
    occupied[idx[:, 0], idx[:, 1]] = True
    distance = distance_transform_edt(~occupied) * resolution
    return Grid(distance <= radius + margin, origin, resolution)


_MOVES = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]


def astar(grid: Grid, start: Sequence[float], goal: Sequence[float]) -> np.ndarray | None:
    """The shortest 8-connected path of free cells (cell centres, start and goal exact), or
    None when the goal cannot be reached."""
    s, g = grid.cell(start), grid.cell(goal)
    if not (grid.free(s) and grid.free(g)):
        return None
    came: dict[tuple[int, int], tuple[int, int]] = {}
    cost = {s: 0.0}
    heap = [(0.0, s)]
    while heap:
        _, cur = heapq.heappop(heap)
        if cur == g:
            cells = [cur]
            while cells[-1] in came:
                cells.append(came[cells[-1]])
            path = [grid.centre(c) for c in reversed(cells)]
            return np.array([np.asarray(start, float), *path[1:-1], np.asarray(goal, float)])
        for di, dj in _MOVES:
            nxt = (cur[0] + di, cur[1] + dj)
            if not grid.free(nxt):
                continue
            c = cost[cur] + math.hypot(di, dj)
            if c < cost.get(nxt, math.inf):
                cost[nxt], came[nxt] = c, cur
                h = math.hypot(g[0] - nxt[0], g[1] - nxt[1])
                heapq.heappush(heap, (c + h, nxt))
    return None


def line_free(grid: Grid, a: np.ndarray, b: np.ndarray) -> bool:
    n = max(2, int(np.linalg.norm(b - a) / (0.25 * grid.resolution)) + 1)
    return all(grid.free(grid.cell(p)) for p in np.linspace(a, b, n))


def shortcut(grid: Grid, path: np.ndarray) -> np.ndarray:
    """Line-of-sight smoothing: from each kept point, jump to the farthest visible one."""
    out, i = [path[0]], 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1 and not line_free(grid, path[i], path[j]):
            j -= 1
        out.append(path[j])
        i = j
    return np.array(out)


def path_length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0


def clearance(
    world: World, path: np.ndarray, z_band: tuple[float, float], spacing: float = 0.02
) -> float:
    """The smallest distance from the path (resampled every ``spacing``) to the true geometry."""
    pts = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(1, math.ceil(np.linalg.norm(b - a) / spacing))
        pts.append(a + (b - a) * np.linspace(0, 1, n + 1)[1:, None])
    return float(world.clearance(np.concatenate(pts), z_band).min())


def _score(
    world: World, path: np.ndarray, success: bool, per_step: float, options: PlannerOptions
) -> dict:
    return {
        "length": round(path_length(path), 3),
        "success": bool(success),
        "min_clearance": round(clearance(world, path, options.z_band), 3),
        "time_per_step_s": per_step,
    }


def evaluate_scene(
    name: str, options: PlannerOptions | None = None, seed: int = 0, n_components: int = 200
) -> tuple[dict, dict]:
    """Scores both planners on one scene; returns (scores, what a plot needs)."""
    from gmmap.io.sim import get_world

    options = options or PlannerOptions()
    world = get_world(name)
    if world.start is None or world.goal is None:
        raise InvalidInputError(f"world {name!r} has no planning task (start and goal)")
    scene = map_scene(world, seed=seed, n_components=n_components)
    start, goal = np.array(world.start[:2]), np.array(world.goal)

    gmm_run: PlanResult = plan(scene.gmm, start, goal, options)
    gmm_score = _score(world, gmm_run.path, gmm_run.success, gmm_run.time_per_step_s, options)
    gmm_score.update(steps=gmm_run.steps, status=gmm_run.status)

    grid = occupancy_grid(scene.points, options.robot_radius, options.z_band)
    t0 = time.perf_counter()
    raw = astar(grid, start, goal)
    path = shortcut(grid, raw) if raw is not None else start[None]
    astar_time = time.perf_counter() - t0
    reached = raw is not None
    astar_score = _score(world, path, reached, astar_time, options)

    scores = {
        "gmm": gmm_score,
        "astar": astar_score,
        "map": {
            "components": len(scene.gmm),
            "submaps": scene.submaps,
            "points": len(scene.points),
        },
    }
    if reached and gmm_run.success:
        scores["length_ratio"] = round(gmm_score["length"] / astar_score["length"], 3)
    return scores, {"world": world, "gmm": scene.gmm, "gmm_path": gmm_run.path, "astar_path": path}


def evaluate_planners(
    scenes: Sequence[str] = SCENES,
    options: PlannerOptions | None = None,
    seed: int = 0,
    plot_dir: str | os.PathLike | None = None,
    progress: Progress | None = None,
    n_components: int = 200,
) -> dict:
    """Table II: both planners on every scene (``gmmap eval planner --json``)."""
    options = options or PlannerOptions()
    result: dict = {"robot_radius": options.robot_radius, "scenes": {}}
    for name in scenes:
        if progress:
            progress(f"{name}: mapping and planning")
        scores, drawing = evaluate_scene(name, options, seed, n_components)
        result["scenes"][name] = scores
        if plot_dir is not None:
            os.makedirs(plot_dir, exist_ok=True)
            scores["png"] = plot_scene(drawing, options, os.path.join(plot_dir, f"{name}.png"))
    return result


def plot_scene(drawing: dict, options: PlannerOptions, path: str) -> str:
    """The occupancy field, its gradient, the true geometry's outline and both paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    world = drawing["world"]
    lo, hi = world.bounds()
    xs, ys = np.arange(lo[0], hi[0], 0.05), np.arange(lo[1], hi[1], 0.05)
    xy = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    occ, grad = OccupancyField(drawing["gmm"], options).gradient(xy)
    truth = world.clearance(xy, options.z_band).reshape(len(ys), len(xs))
    fig, ax = plt.subplots(figsize=(8, 8 * len(ys) / len(xs) + 0.6))
    extent = (xs[0], xs[-1], ys[0], ys[-1])
    ax.imshow(occ.reshape(len(ys), len(xs)), origin="lower", extent=extent, cmap="Greys")
    ax.contour(xs, ys, truth, levels=[0.0], colors="tab:red", linewidths=0.8)
    q = slice(None, None, 6)
    gx, gy = (grad[:, i].reshape(len(ys), len(xs))[q, q] for i in (0, 1))
    ax.quiver(xs[q], ys[q], gx, gy, color="tab:blue", alpha=0.5, width=0.002)
    for key, label in (("astar_path", "A*"), ("gmm_path", "GMM")):
        p = drawing[key]
        ax.plot(p[:, 0], p[:, 1], lw=2, label=label)
    ax.plot(*world.start[:2], "ko")
    ax.plot(*world.goal, "k*", ms=12)
    ax.set(xlabel="x (m)", ylabel="y (m)", title=f"{world.name}: occupancy, gradient, paths")
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize="small")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
