"""The GMM gradient-field planner and its A* baseline (paper V-C, Table II)."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gmmap import Gmm, InvalidInputError
from gmmap.cli import main
from gmmap.eval.planner import astar, evaluate_scene, occupancy_grid, shortcut
from gmmap.mapping.planner import GradientPlanner, OccupancyField, PlannerOptions, Route, plan

RADIUS = PlannerOptions().robot_radius


def segment_gmm(segments, piece=0.25, z=0.6, thickness=0.01):
    """Walls as a GMM: each (x0, y0, x1, y1) split into pieces, one thin component each, the
    spread a uniform piece of wall has (length^2 / 12 along, 0.35 m over the height)."""
    means, covs = [], []
    for x0, y0, x1, y1 in segments:
        a, b = np.array([x0, y0]), np.array([x1, y1])
        n = max(1, round(np.linalg.norm(b - a) / piece))
        u = (b - a) / np.linalg.norm(b - a)
        rot = np.array([[u[0], -u[1], 0], [u[1], u[0], 0], [0, 0, 1]])
        length = np.linalg.norm(b - a) / n
        for t in (np.arange(n) + 0.5) / n:
            means.append([*(a + t * (b - a)), z])
            covs.append(rot @ np.diag([length**2 / 12, thickness**2, 0.35**2]) @ rot.T)
    k = len(means)
    return Gmm(np.full(k, 1 / k), np.array(means), np.array(covs))


def floor_gmm():
    """Only floor: nothing in the robot's height band."""
    means = [[x, y, 0.0] for x in range(5) for y in range(-2, 3)]
    covs = [np.diag([0.3, 0.3, 1e-4])] * len(means)
    return Gmm(np.full(len(means), 1 / len(means)), np.array(means), np.array(covs))


def distance_to_segments(path, segments):
    best = np.inf
    for x0, y0, x1, y1 in segments:
        a, b = np.array([x0, y0]), np.array([x1, y1])
        t = np.clip((path - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        best = min(best, np.linalg.norm(path - (a + t[:, None] * (b - a)), axis=1).min())
    return best


def test_straight_line_in_an_empty_world():
    r = plan(floor_gmm(), (0.0, 0.0), (4.0, 0.0))
    assert r.success and r.status == "reached"
    assert np.allclose(r.path[:, 1], 0.0, atol=1e-9)
    assert r.length == pytest.approx(4.0 - PlannerOptions().goal_tolerance, abs=0.11)


def test_a_wall_ahead_causes_a_detour_without_collision():
    wall = [(2.0, -1.0, 2.0, 1.0)]
    r = plan(segment_gmm(wall), (0.0, 0.0), (4.0, 0.0))
    assert r.success
    assert np.abs(r.path[:, 1]).max() > 1.0  # it went round the wall's end
    assert distance_to_segments(r.path, wall) > RADIUS


def test_a_doorway_wider_than_the_robot_is_passed():
    walls = [(2.0, -3.0, 2.0, -0.45), (2.0, 0.45, 2.0, 3.0)]
    r = plan(segment_gmm(walls), (0.0, 0.0), (4.0, 0.0))
    assert r.success and np.abs(r.path[:, 1]).max() < 0.3
    assert distance_to_segments(r.path, walls) > RADIUS


def test_an_unreachable_goal_ends_stuck_not_in_a_loop():
    box = [(3, -1, 5, -1), (5, -1, 5, 1), (5, 1, 3, 1), (3, 1, 3, -1)]
    options = PlannerOptions(max_steps=5000)
    r = plan(segment_gmm(box), (0.0, 0.0), (4.0, 0.0), options)
    assert r.status == "stuck" and not r.success and r.reason
    assert r.steps < options.max_steps
    assert distance_to_segments(r.path, box) > RADIUS


def follow(route: Route, field: OccupancyField, start) -> tuple[bool, np.ndarray]:
    """An explorer's steps along ``route`` on ``field``: whether it arrived, and the path."""
    options, position = PlannerOptions(), np.array(start, dtype=float)
    path = [position]
    while (target := route.next_waypoint(position)) is not None:
        direction = route.steer(position, target, options, field)
        if direction is None:
            return False, np.array(path)
        position = position + min(options.step, np.linalg.norm(target - position)) * direction
        path.append(position)
    return True, np.array(path)


@pytest.mark.parametrize(("pocket", "first_into"), [(1.0, True), (-1.0, False)])
def test_a_route_round_the_closed_side_of_a_wall_turns_back_round_the_open_side(pocket, first_into):
    """A wall across the way, open 1 m to one side and closed into a pocket on the other
    (a door jamb beside a wall): whichever side the route takes first, it arrives; where it
    took the pocket (to the left, from the wall's middle), it turned back once."""
    walls = [(3.0, -pocket, 3.0, 3.0 * pocket), (1.5, 3.0 * pocket, 3.0, 3.0 * pocket)]
    goal = np.array([6.0, 0.0])
    route = Route(goal[None], goal, 0.0)
    arrived, path = follow(route, OccupancyField(segment_gmm(walls), PlannerOptions()), (0, 0))
    assert arrived and distance_to_segments(path, walls) > RADIUS
    assert route.turned_back == first_into == ((path[:, 1] * pocket).max() > 1.5)
    # Without the second side, the route that went into the pocket gives up.
    again = Route(goal[None], goal, 0.0, turned_back=True)
    field = OccupancyField(segment_gmm(walls), PlannerOptions())
    assert follow(again, field, (0, 0))[0] != first_into


def test_analytic_gradient_matches_finite_differences():
    rng = np.random.default_rng(3)
    walls = [tuple(rng.uniform(-2, 2, 4)) for _ in range(4)]
    field = OccupancyField(segment_gmm(walls, piece=0.5))
    xy = rng.uniform(-2, 2, (40, 2))
    occ, grad = field.gradient(xy)
    h = 1e-6
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = h
        fd = (field.occupancy(xy + step) - field.occupancy(xy - step)) / (2 * h)
        assert np.allclose(grad[:, axis], fd, rtol=1e-4, atol=1e-6)
    assert (occ >= 0).all()
    far_occ, far_grad = field.gradient([(30.0, 30.0), (1e3, -1e3)])  # terms underflow there
    assert np.isfinite(far_grad).all() and np.allclose(far_occ, 0.0)


def test_occupancy_is_high_on_a_surface_and_the_level_at_radius_plus_margin():
    options = PlannerOptions()
    field = OccupancyField(segment_gmm([(0, -2, 0, 2)], piece=4.0, thickness=1e-3), options)
    at = options.robot_radius + options.margin
    occ = field.occupancy([(0.0, 0.0), (at, 0.0), (1.0, 0.0)])
    assert occ[0] > 0.99 and occ[1] == pytest.approx(options.max_occupancy, abs=0.01)
    assert occ[2] < 0.01


def test_floor_and_ceiling_components_are_outside_the_band():
    assert len(OccupancyField(floor_gmm())) == 0
    assert plan(floor_gmm(), (0, 0), (1, 1)).success


def test_bad_input_is_a_clear_error():
    with pytest.raises(InvalidInputError):
        plan(floor_gmm(), (np.nan, 0.0), (1.0, 0.0))
    with pytest.raises(InvalidInputError):
        PlannerOptions(z_band=(1.0, 0.5))
    with pytest.raises(InvalidInputError):
        PlannerOptions(max_occupancy=1.5)
    with pytest.raises(InvalidInputError):
        GradientPlanner(floor_gmm()).field.occupancy(np.zeros((3, 3)))


def wall_points(x=2.0, y0=-1.0, y1=1.0):
    y, z = np.meshgrid(np.arange(y0, y1, 0.02), np.arange(0.1, 1.0, 0.1))
    return np.stack([np.full(y.size, x), y.ravel(), z.ravel()], axis=1)


def test_astar_goes_round_an_inflated_wall_and_reports_no_path():
    grid = occupancy_grid(np.vstack([wall_points(), [[0, -2, 0.5], [4, 2, 0.5]]]), RADIUS, (0, 1))
    path = astar(grid, (0.0, 0.0), (4.0, 0.0))
    assert path is not None and np.abs(path[:, 1]).max() > 1.0 + RADIUS
    smooth = shortcut(grid, path)
    assert len(smooth) < len(path) and smooth[0] == pytest.approx([0, 0])
    walled = occupancy_grid(wall_points(2.0, -3, 3), RADIUS, (0, 1))
    assert astar(walled, (0.0, 0.0), (4.0, 0.0)) is None


def test_corner_scene_both_planners_succeed_without_collision():
    scores, _ = evaluate_scene("corner")
    for method in ("gmm", "astar"):
        assert scores[method]["success"], scores
        assert scores[method]["min_clearance"] > RADIUS, scores
    assert scores["gmm"]["length"] < 1.1 * scores["astar"]["length"]


def test_eval_planner_cli_json_keys(tmp_path):
    result = CliRunner().invoke(
        main,
        ["eval", "planner", "--scenes", "passage", "--json", "--plots", str(tmp_path)],
        catch_exceptions=False,
    )
    assert result.exit_code == 0, result.output
    r = json.loads(result.output.strip().splitlines()[-1])
    assert r["robot_radius"] == RADIUS
    scene = r["scenes"]["passage"]
    for method in ("gmm", "astar"):
        assert set(scene[method]) >= {"length", "success", "min_clearance", "time_per_step_s"}
    assert (tmp_path / "passage.png").stat().st_size > 10_000
