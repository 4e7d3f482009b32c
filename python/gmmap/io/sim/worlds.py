"""Built-in worlds: ``office`` (the demo's world), the four planner scenes of the paper's
Table II (``corner``, ``passage``, ``clutter`` and ``front-obstacle``) and ``two-storey``, for
an aerial robot."""

from __future__ import annotations

import math

from gmmap.errors import InvalidInputError
from gmmap.io.sim.world import (
    WALL_HEIGHT,
    Box,
    Cylinder,
    Shape,
    World,
    cabinet,
    chair,
    pillar,
    shelf,
    slab,
    table,
    wall,
)


def _enclosure(x0: float, y0: float, x1: float, y1: float, ceiling: bool = True) -> list[Shape]:
    """Floor, ceiling and four outer walls."""
    shapes: list[Shape] = [slab(x0, y0, x1, y1, -0.025)]
    if ceiling:
        shapes.append(slab(x0, y0, x1, y1, WALL_HEIGHT + 0.025))
    for a, b in [
        ((x0, y0), (x1, y0)),
        ((x1, y0), (x1, y1)),
        ((x1, y1), (x0, y1)),
        ((x0, y1), (x0, y0)),
    ]:
        shapes += wall(*a, *b)
    return shapes


def office() -> World:
    """A 20 m x 10 m office: five rooms off a 2 m corridor, furniture, pillars.

    Rooms A, B, C lie south of the corridor (y 0-4), D and E north of it (y 6-10). Each robot
    route starts in a different room, crosses part of the corridor and enters another robot's
    room, so every pair of the first three robots shares places. Room widths (6, 7.5, 6.5 m)
    and door positions are irregular on purpose: a strictly periodic office (equal rooms, doors
    every 7 m) is ambiguous by construction, since a submap then fits as well one room over,
    which no place recognition or registration can resolve.
    """
    s = _enclosure(0, 0, 20, 10)
    s += wall(0, 4, 20, 4, doors=((2.5, 1.0), (9.0, 1.0), (16.5, 1.0)))
    s += wall(0, 6, 20, 6, doors=((4.2, 1.0), (15.5, 1.0)))
    s += wall(6, 0, 6, 4) + wall(13.5, 0, 13.5, 4) + wall(11, 6, 11, 10)
    # Room A: a desk with chairs, a shelf on the west wall, a cabinet.
    s += table(2.0, 1.4) + chair(2.0, 2.1, -math.pi / 2) + chair(1.2, 1.4)
    s += shelf(0.3, 2.6, yaw=math.pi / 2) + cabinet(5.4, 0.5)
    # Room B: two tables, chairs, a shelf against the south wall.
    s += table(8.8, 1.5) + table(12.2, 1.5, yaw=0.3) + chair(8.8, 2.2, -math.pi / 2)
    s += chair(12.0, 2.3, -math.pi / 2) + shelf(10.5, 0.3, w=1.6)
    # Room C: a pillar, a table, cabinets.
    s += pillar(17.5, 1.8, 0.25) + table(15.5, 1.0, w=1.2) + cabinet(19.4, 2.6, yaw=math.pi / 2)
    s += cabinet(19.4, 1.5, yaw=math.pi / 2)
    # Room D: a meeting table with chairs, shelves on the north wall.
    s += table(4.5, 8.2, w=3.0, d=1.2)
    s += [p for x in (3.5, 4.5, 5.5) for p in chair(x, 7.3, math.pi / 2)]
    s += shelf(1.5, 9.7) + shelf(2.7, 9.7) + cabinet(9.4, 9.5)
    # Room E: two desks, a pillar, a cabinet row.
    s += table(13.0, 8.6, yaw=math.pi / 2) + table(18.0, 8.0) + pillar(16.0, 7.4)
    s += chair(18.0, 7.2, math.pi / 2) + cabinet(19.5, 9.0, yaw=math.pi / 2)
    s += cabinet(11.8, 9.6)
    # Corridor: a pillar against each of its walls; a copier bank and a stair core at the
    # east end (a corridor looks the same end for end without them).
    s += pillar(7.9, 5.75, 0.15) + pillar(12.2, 4.25, 0.15)
    s += cabinet(19.55, 4.75, w=1.3, d=0.7, h=1.3, yaw=math.pi / 2)
    s += [Box((19.2, 5.6, WALL_HEIGHT / 2), (1.6, 0.7, WALL_HEIGHT))]
    routes = [
        [(1.5, 2.6), (2.5, 3.0), (2.5, 5.0), (9.0, 5.0), (9.0, 3.0), (11.5, 2.6)],  # A → B
        [(10.0, 3.0), (9.0, 3.3), (9.0, 5.0), (15.5, 5.0), (15.5, 6.8), (17.0, 6.8)],  # B → E
        [(17.0, 9.0), (15.5, 8.2), (15.5, 5.0), (4.2, 5.0), (4.2, 6.6), (3.0, 6.6)],  # E → D
        [(16.0, 3.0), (16.5, 3.3), (16.5, 5.0), (9.0, 5.0), (9.0, 3.0), (10.2, 2.8)],  # C → B
        [(2.5, 6.6), (4.2, 6.6), (4.2, 5.0), (16.5, 5.0), (16.5, 3.0)],  # D → C
    ]
    return World("office", s, routes)


def corner() -> World:
    """A 2 m wide corridor with a right-angle turn: start in one arm, goal in the other."""
    s = [slab(0, 0, 8, 8, -0.025)]
    s += wall(0, 0, 8, 0) + wall(8, 0, 8, 8) + wall(8, 8, 6, 8)
    s += wall(6, 8, 6, 2) + wall(6, 2, 0, 2) + wall(0, 2, 0, 0)
    return World("corner", s, [[(0.6, 1.0), (7.0, 1.0), (7.0, 7.4)]], (0.6, 1.0, 0.0), (7.0, 7.2))


def passage() -> World:
    """An open hall split by a wall with a 1.2 m passageway the robot must go through."""
    s = _enclosure(0, -3, 10, 3, ceiling=False)
    s += wall(5, -3, 5, 3, doors=((3.0, 1.2),))
    s += [Box((5.0, -0.6, 0.5), (0.6, 0.05, 1.0)), Box((5.0, 0.6, 0.5), (0.6, 0.05, 1.0))]
    return World("passage", s, [[(0.6, 0.0), (9.4, 0.0)]], (0.6, 0.0, 0.0), (9.4, 0.0))


def clutter() -> World:
    """A 10 m x 8 m room with boxes and pillars scattered between start and goal."""
    s = _enclosure(0, 0, 10, 8, ceiling=False)
    boxes = [
        (2.5, 4.6, 0.8, 0.6, 0.3),
        (3.3, 2.9, 0.6, 0.6, 0.0),
        (4.8, 5.4, 1.0, 0.5, 0.8),
        (5.6, 3.4, 0.7, 0.7, 0.4),
        (7.2, 4.4, 0.6, 1.0, 0.0),
        (6.4, 2.0, 0.8, 0.5, 1.2),
    ]
    s += [Box((x, y, 0.5), (w, d, 1.0), yaw) for x, y, w, d, yaw in boxes]
    for x, y in [(1.8, 3.2), (4.0, 4.2), (6.2, 5.8), (7.8, 2.8), (8.3, 5.3), (3.4, 6.0)]:
        s += pillar(x, y, 0.15, 1.5)
    route = [(0.7, 4.0), (0.7, 0.8), (9.3, 0.8), (9.3, 7.2), (0.7, 7.2), (0.7, 4.0)]
    return World("clutter", s, [route], (0.7, 4.0, 0.0), (9.3, 4.0))


def front_obstacle() -> World:
    """A 3 m wide corridor with a wide obstacle straight ahead of the robot."""
    s = [slab(0, -1.5, 10, 1.5, -0.025)]
    s += wall(0, -1.5, 10, -1.5) + wall(0, 1.5, 10, 1.5)
    s += wall(0, -1.5, 0, 1.5) + wall(10, -1.5, 10, 1.5)
    s += [Box((5.0, 0.0, 0.5), (0.8, 1.2, 1.0))]
    route = [(0.6, -1.05), (9.4, -1.05), (9.4, 1.05), (0.6, 1.05)]
    return World("front-obstacle", s, [route], (0.6, 0.0, 0.0), (9.4, 0.0))


STOREY = 3.0  # metres from one floor to the next in ``two-storey``


def _raised(shapes: list[Shape], dz: float) -> list[Shape]:
    """Furniture moved up onto an upper storey's floor."""
    return [
        Box((s.centre[0], s.centre[1], s.centre[2] + dz), s.size, s.yaw)
        if isinstance(s, Box)
        else Cylinder(s.x, s.y, s.radius, s.z_min + dz, s.z_max + dz)
        for s in shapes
    ]


def two_storey() -> World:
    """A 12 m x 8 m building of two 3 m storeys for an aerial robot: three rooms and a hall on
    the ground floor, three rooms and a gallery upstairs, joined only by a 3 m x 2.5 m void in
    the floor between them (x 8.5-11.5, y 5-7.5). Robots start in the ground-floor hall; its
    route, for a ground robot, crosses the hall under the void."""
    top, base = 2 * STOREY, STOREY + 0.05
    s: list[Shape] = [slab(0, 0, 12, 8, -0.025), slab(0, 0, 12, 8, top + 0.025)]
    for a, b in [((0, 0), (12, 0)), ((12, 0), (12, 8)), ((12, 8), (0, 8)), ((0, 8), (0, 0))]:
        s += wall(*a, *b, height=top)
    # The floor between the storeys, around the void.
    for x0, y0, x1, y1 in [(0, 0, 12, 5), (0, 7.5, 12, 8), (0, 5, 8.5, 7.5), (11.5, 5, 12, 7.5)]:
        s.append(slab(x0, y0, x1, y1, STOREY, thickness=0.1))
    # Ground floor: rooms A, B, C south of the hall (y 4-8).
    low = STOREY - 0.05
    s += wall(0, 4, 12, 4, doors=((2.2, 1.0), (6.3, 1.0), (10.4, 1.0)), height=low)
    s += wall(4.5, 0, 4.5, 4, height=low) + wall(8.5, 0, 8.5, 4, doors=((1.2, 0.9),), height=low)
    s += table(2.2, 1.6) + shelf(0.3, 2.4, yaw=math.pi / 2) + cabinet(7.8, 0.5)
    s += table(10.5, 1.8, w=1.2, yaw=0.4) + pillar(3.0, 6.2, 0.2, low) + cabinet(6.0, 7.6)
    # Upper storey: rooms D, E, F south of a gallery round the void, a study north-west.
    s += wall(0, 4, 12, 4, doors=((1.6, 1.0), (7.2, 1.0), (10.8, 1.0)), height=low, base=base)
    s += wall(3.5, 0, 3.5, 4, height=low, base=base)
    s += wall(8.0, 0, 8.0, 4, doors=((2.8, 0.9),), height=low, base=base)
    s += wall(5.0, 4, 5.0, 8, doors=((2.0, 1.0),), height=low, base=base)
    up = table(1.8, 1.8, yaw=math.pi / 2) + shelf(5.7, 0.3, w=1.6) + cabinet(11.4, 3.4)
    up += table(2.5, 6.5, w=1.2) + pillar(7.0, 6.8, 0.2, low) + cabinet(9.8, 0.5)
    s += _raised(up, base)
    route = [(1.0, 5.2), (8.0, 5.2), (8.0, 6.8), (11.0, 6.8)]  # a ground robot's, in the hall
    return World("two-storey", s, [route], start=(2.5, 5.5, 0.0), goal=(11.0, 6.8))


WORLDS = {
    "office": office,
    "corner": corner,
    "passage": passage,
    "clutter": clutter,
    "front-obstacle": front_obstacle,
    "two-storey": two_storey,
}


def load_world(name: str) -> World:
    """A world file (``.json``, `World.save`) or a world `get_world` knows by name."""
    return World.load(name) if name.endswith(".json") else get_world(name)


def get_world(name: str) -> World:
    """A built-in world by name, or a procedural office, ``random-office:<seed>``
    (`gmmap.io.sim.procedural`)."""
    from gmmap.io.sim.procedural import PREFIX, random_office

    if name.startswith(PREFIX):
        try:
            return random_office(int(name[len(PREFIX) :]))
        except ValueError:
            raise InvalidInputError(f"{name!r}: the seed after {PREFIX!r} is an integer") from None
    try:
        return WORLDS[name]()
    except KeyError:
        raise InvalidInputError(
            f"unknown world {name!r}; built-in: {', '.join(WORLDS)}, or {PREFIX}<seed>"
        ) from None
