"""Procedural offices: a family of worlds drawn from a seed (``random-office:<seed>``), for
training and testing learned place recognition on worlds it has never seen.

Each is the demo office's layout made random: rooms of random widths and depths south and
north of one corridor of random width, a door per room at a random place, furniture of random
kinds and poses in the back of each room (the front stays clear for the routes), pillars and a
cabinet bank in the corridor. Robot ``i`` starts inside room ``i``, leaves through its door,
follows the corridor and enters the room the next robot starts in, so consecutive robots share
places, as in the demo office.
"""

from __future__ import annotations

import math

import numpy as np

from gmmap.io.sim.world import World, cabinet, chair, pillar, shelf, table, wall
from gmmap.io.sim.worlds import _enclosure

PREFIX = "random-office:"
DOOR_W = 1.0
CLEAR = 1.9  # metres in front of a room's corridor wall kept free of furniture


def _widths(rng: np.random.Generator, total: float, n: int, least: float = 3.5) -> list[float]:
    """``n`` room widths of at least ``least`` summing to ``total``."""
    spare = total - n * least
    cuts = np.sort(rng.uniform(0, spare, n - 1))
    return [least + float(b - a) for a, b in zip(np.r_[0, cuts], np.r_[cuts, spare], strict=True)]


def _furnish(rng: np.random.Generator, x0: float, x1: float, back: float, front: float) -> list:
    """Furniture between the back wall (y ``back``) and the clear strip ending at ``front``."""
    inward = 1.0 if front > back else -1.0
    depth = abs(front - back)
    shapes: list = []
    x = x0 + 0.4 + rng.uniform(0, 0.6)
    while x < x1 - 1.0:
        kind = rng.choice(["table", "shelf", "cabinet", "pillar", "none"])
        y = back + inward * rng.uniform(0.35, max(0.4, depth - 0.6))
        yaw = float(rng.uniform(-0.4, 0.4))
        if kind == "table" and x + 1.5 < x1:
            shapes += table(x + 0.7, y, yaw=yaw)
            if rng.random() < 0.7:
                shapes += chair(x + 0.7, y + inward * 0.7, -inward * math.pi / 2)
            x += 1.9
        elif kind == "shelf":
            shapes += shelf(x + 0.5, back + inward * 0.25, w=float(rng.uniform(0.8, 1.6)))
            x += 1.8
        elif kind == "cabinet":
            shapes += cabinet(x + 0.4, back + inward * 0.3, h=float(rng.uniform(0.7, 1.8)))
            x += 1.2
        elif kind == "pillar":
            shapes += pillar(x + 0.3, y, float(rng.uniform(0.12, 0.3)))
            x += 1.2
        else:
            x += 1.0
    return shapes


def random_office(seed: int) -> World:
    """The procedural office of ``seed`` (the same world for the same seed)."""
    rng = np.random.default_rng([seed, 0x0FF1CE])
    width = float(rng.uniform(16.0, 26.0))
    south, corridor, north = (float(v) for v in rng.uniform([3.6, 1.8, 3.6], [5.0, 2.8, 5.0]))
    y_s, y_n = south, south + corridor  # the corridor's walls
    mid = 0.5 * (y_s + y_n)
    shapes = _enclosure(0, 0, width, y_n + north)
    rooms = []  # (x0, x1, door x, room-side y of the route, back wall y, clear strip end)
    doors: dict[float, list[tuple[float, float]]] = {y_s: [], y_n: []}
    sides = ((y_s, 0.0, int(rng.integers(2, 5))), (y_n, y_n + north, int(rng.integers(2, 4))))
    for wall_y, back, n in sides:
        inward = -1.0 if back < wall_y else 1.0
        x = 0.0
        for w in _widths(rng, width, n):
            door = x + float(rng.uniform(0.9, w - 0.9))
            doors[wall_y].append((door, DOOR_W))
            rooms.append((x, x + w, door, wall_y + inward * 1.2, back, wall_y + inward * CLEAR))
            if x > 0:
                shapes += wall(x, wall_y, x, back)
            x += w
    for wall_y, gaps in doors.items():
        shapes += wall(0, wall_y, width, wall_y, doors=tuple(gaps))
    for x0, x1, _, _, back, front in rooms:
        shapes += _furnish(rng, x0, x1, back, front)
    # The corridor: a pillar against each wall and a cabinet bank at one end, so that it does
    # not look the same end for end.
    for wall_y, side in ((y_s, 1.0), (y_n, -1.0)):
        free = [x for x in np.arange(2.0, width - 2.0, 0.25)
                if all(abs(x - d) > 1.0 for d, _ in doors[wall_y])]  # fmt: skip
        if free:
            shapes += pillar(float(rng.choice(free)), wall_y + side * 0.25, 0.15)
    end = 0.45 if rng.random() < 0.5 else width - 0.45
    shapes += cabinet(end, mid, w=float(rng.uniform(0.8, 1.6)), d=0.6, h=1.3, yaw=math.pi / 2)
    order = rng.permutation(len(rooms))
    routes = []
    for k in range(len(rooms)):
        a, b = rooms[order[k]], rooms[order[(k + 1) % len(rooms)]]
        inside_a = (float(np.clip(a[2] - 1.2, a[0] + 0.6, a[1] - 0.6)), a[3])
        inside_b = (float(np.clip(b[2] + 1.2, b[0] + 0.6, b[1] - 0.6)), b[3])
        routes.append([inside_a, (a[2], a[3]), (a[2], mid), (b[2], mid), (b[2], b[3]), inside_b])
    return World(f"{PREFIX}{seed}", shapes, routes)
