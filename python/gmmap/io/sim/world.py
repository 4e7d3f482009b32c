"""Worlds of primitives for the simulator, defined in code or in a small JSON file.

Coordinates are metres in a gravity-aligned world frame (z up, floor at z = 0). Two primitives
cover offices and planner scenes: yawed boxes (walls, floor, ceiling, furniture parts) and
upright cylinders (pillars, table legs). Ray casting runs in the Rust core.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from gmmap import _core
from gmmap.errors import FileFormatError, InvalidInputError


@dataclass(frozen=True)
class Box:
    centre: tuple[float, float, float]
    size: tuple[float, float, float]  # full extents along the box's own x, y, z
    yaw: float = 0.0  # rotation about +z, radians


@dataclass(frozen=True)
class Cylinder:
    x: float
    y: float
    radius: float
    z_min: float
    z_max: float


Shape = Box | Cylinder


@dataclass
class World:
    """A named scene: shapes, mapping routes for robots, and an optional planner task.

    ``routes`` are (x, y) waypoint lists, one per robot (robots beyond them reuse them with
    offsets); ``start`` (x, y, yaw) and ``goal`` (x, y) define a planning task.
    """

    name: str
    shapes: list[Shape] = field(default_factory=list)
    routes: list[list[tuple[float, float]]] = field(default_factory=list)
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float] | None = None

    @cached_property
    def scene(self) -> _core.RayScene:
        """The Rust ray-casting scene (a BVH), built once."""
        boxes = [
            (*s.centre, *(0.5 * v for v in s.size), s.yaw)
            for s in self.shapes
            if isinstance(s, Box)
        ]
        cyls = [
            (s.x, s.y, s.radius, s.z_min, s.z_max) for s in self.shapes if isinstance(s, Cylinder)
        ]
        return _core.RayScene(
            np.array(boxes, float).reshape(-1, 7), np.array(cyls, float).reshape(-1, 5)
        )

    def in_sight(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether nothing of the world stands between points ``a`` and ``b``."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        gap = float(np.linalg.norm(b - a))
        if gap == 0.0:
            return True
        origin = np.eye(4)
        origin[:3, 3] = a
        return bool(np.isnan(self.scene.ranges(origin, ((b - a) / gap)[None], gap)[0]))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned (min, max) corners of all shapes."""
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for s in self.shapes:
            if isinstance(s, Box):
                c, h = np.array(s.centre), 0.5 * np.array(s.size)
                ext = np.array(
                    [
                        abs(math.cos(s.yaw)) * h[0] + abs(math.sin(s.yaw)) * h[1],
                        abs(math.sin(s.yaw)) * h[0] + abs(math.cos(s.yaw)) * h[1],
                        h[2],
                    ]
                )
                a, b = c - ext, c + ext
            else:
                a = np.array([s.x - s.radius, s.y - s.radius, s.z_min])
                b = np.array([s.x + s.radius, s.y + s.radius, s.z_max])
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        return lo, hi

    def clearance(self, xy: object, z_band: tuple[float, float] = (0.05, 1.8)) -> np.ndarray:
        """Signed horizontal distance from (N, 2) points to the nearest shape that occupies the
        height band (negative inside a shape): the true geometry a planner must keep clear of."""
        pts = np.atleast_2d(np.asarray(xy, dtype=np.float64))
        best = np.full(len(pts), np.inf)
        for s in self.shapes:
            if isinstance(s, Box):
                z0, z1 = s.centre[2] - s.size[2] / 2, s.centre[2] + s.size[2] / 2
                if z1 < z_band[0] or z0 > z_band[1]:
                    continue
                c, sn = math.cos(s.yaw), math.sin(s.yaw)
                p = pts - np.array(s.centre[:2])
                local = np.stack([c * p[:, 0] + sn * p[:, 1], -sn * p[:, 0] + c * p[:, 1]], 1)
                q = np.abs(local) - 0.5 * np.array(s.size[:2])
                d = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
            else:
                if s.z_max < z_band[0] or s.z_min > z_band[1]:
                    continue
                d = np.linalg.norm(pts - [s.x, s.y], axis=1) - s.radius
            best = np.minimum(best, d)
        return best

    def distance(self, xyz: object) -> np.ndarray:
        """Signed 3D distance from (N, 3) points to the nearest shape (negative inside one):
        the true geometry an aerial robot must keep clear of."""
        pts = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
        best = np.full(len(pts), np.inf)
        for s in self.shapes:
            if isinstance(s, Box):
                c, sn = math.cos(s.yaw), math.sin(s.yaw)
                p = pts - np.array(s.centre)
                local = np.stack(
                    [c * p[:, 0] + sn * p[:, 1], -sn * p[:, 0] + c * p[:, 1], p[:, 2]], 1
                )
                q = np.abs(local) - 0.5 * np.array(s.size)
            else:
                radial = np.linalg.norm(pts[:, :2] - [s.x, s.y], axis=1) - s.radius
                middle, half = 0.5 * (s.z_min + s.z_max), 0.5 * (s.z_max - s.z_min)
                q = np.stack([radial, np.abs(pts[:, 2] - middle) - half], 1)
            d = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
            best = np.minimum(best, d)
        return best

    def to_dict(self) -> dict:
        shapes = [
            {"type": "box", "centre": list(s.centre), "size": list(s.size), "yaw": s.yaw}
            if isinstance(s, Box)
            else {
                "type": "cylinder",
                "x": s.x,
                "y": s.y,
                "radius": s.radius,
                "z_min": s.z_min,
                "z_max": s.z_max,
            }
            for s in self.shapes
        ]
        return {
            "name": self.name,
            "shapes": shapes,
            "routes": [list(map(list, r)) for r in self.routes],
            "start": self.start,
            "goal": self.goal,
        }

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def load(cls, path: str | Path) -> World:
        """Reads a world file; malformed content raises FileFormatError naming the file."""
        try:
            return cls.from_dict(json.loads(Path(path).read_text()))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise FileFormatError(f"{path}: not a valid world file ({exc})") from exc

    @classmethod
    def from_dict(cls, d: dict) -> World:
        shapes: list[Shape] = []
        for s in d["shapes"]:
            if s["type"] == "box":
                shape: Shape = Box(_vec(s["centre"], 3), _vec(s["size"], 3), float(s.get("yaw", 0)))
                if min(shape.size) <= 0:
                    raise ValueError(f"box sizes must be positive: {s}")
            elif s["type"] == "cylinder":
                shape = Cylinder(*(float(s[k]) for k in ("x", "y", "radius", "z_min", "z_max")))
                if shape.radius <= 0 or shape.z_max <= shape.z_min:
                    raise ValueError(f"bad cylinder: {s}")
            else:
                raise ValueError(f"unknown shape type {s['type']!r}")
            shapes.append(shape)
        routes = [[_vec(p, 2) for p in r] for r in d.get("routes", [])]
        start = _vec(d["start"], 3) if d.get("start") is not None else None
        goal = _vec(d["goal"], 2) if d.get("goal") is not None else None
        return cls(str(d["name"]), shapes, routes, start, goal)


def _vec(v: object, n: int) -> tuple[float, ...]:
    out = tuple(float(x) for x in v)  # type: ignore[union-attr]
    if len(out) != n or not all(math.isfinite(x) for x in out):
        raise ValueError(f"expected {n} finite numbers, got {v!r}")
    return out


# Builders: the vocabulary the built-in worlds are written in.

WALL_HEIGHT = 2.6
WALL_THICKNESS = 0.1


def wall(
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    doors: tuple[tuple[float, float], ...] = (),
    height: float = WALL_HEIGHT,
    base: float = 0.0,
) -> list[Box]:
    """A straight wall from (x0, y0) to (x1, y1) with door gaps (centre along wall, width),
    standing on ``base`` (an upper storey's floor)."""
    length = math.hypot(x1 - x0, y1 - y0)
    if length <= 0:
        raise InvalidInputError("a wall needs two distinct end points")
    yaw = math.atan2(y1 - y0, x1 - x0)
    cuts = sorted((c - w / 2, c + w / 2) for c, w in doors)
    pieces, pos = [], 0.0
    for a, b in [*cuts, (length, length)]:
        if a - pos > 1e-6:
            mid = 0.5 * (pos + a)
            pieces.append(
                Box(
                    (x0 + math.cos(yaw) * mid, y0 + math.sin(yaw) * mid, base + height / 2),
                    (a - pos, WALL_THICKNESS, height),
                    yaw,
                )
            )
        pos = max(pos, b)
    return pieces


def slab(x0: float, y0: float, x1: float, y1: float, z: float, thickness: float = 0.05) -> Box:
    """A horizontal slab (floor, ceiling, table top) over [x0, x1] x [y0, y1] centred at z."""
    return Box((0.5 * (x0 + x1), 0.5 * (y0 + y1), z), (x1 - x0, y1 - y0, thickness))


def table(
    x: float, y: float, w: float = 1.4, d: float = 0.8, h: float = 0.75, yaw: float = 0.0
) -> list[Shape]:
    """A top and four legs."""
    c, s = math.cos(yaw), math.sin(yaw)
    legs: list[Shape] = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            lx, ly = sx * (w / 2 - 0.06), sy * (d / 2 - 0.06)
            legs.append(Cylinder(x + c * lx - s * ly, y + s * lx + c * ly, 0.03, 0.0, h - 0.03))
    return [Box((x, y, h - 0.015), (w, d, 0.03), yaw), *legs]


def chair(x: float, y: float, yaw: float = 0.0) -> list[Shape]:
    """A seat on a post, with a backrest on the far side (-x in the chair's frame)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return [
        Box((x, y, 0.45), (0.45, 0.45, 0.05), yaw),
        Cylinder(x, y, 0.03, 0.0, 0.43),
        Box((x - 0.2 * c, y - 0.2 * s, 0.7), (0.05, 0.45, 0.5), yaw),
    ]


def shelf(
    x: float,
    y: float,
    w: float = 1.0,
    d: float = 0.35,
    h: float = 1.8,
    yaw: float = 0.0,
    boards: int = 4,
) -> list[Shape]:
    """Two sides and `boards` horizontal boards."""
    c, s = math.cos(yaw), math.sin(yaw)
    sides = [
        Box((x + c * sx * (w / 2), y + s * sx * (w / 2), h / 2), (0.03, d, h), yaw)
        for sx in (-1, 1)
    ]
    return [
        *sides,
        *(
            Box((x, y, 0.05 + i * (h - 0.1) / (boards - 1)), (w, d, 0.03), yaw)
            for i in range(boards)
        ),
    ]


def cabinet(
    x: float, y: float, w: float = 0.8, d: float = 0.5, h: float = 1.1, yaw: float = 0.0
) -> list[Shape]:
    return [Box((x, y, h / 2), (w, d, h), yaw)]


def pillar(x: float, y: float, radius: float = 0.2, height: float = WALL_HEIGHT) -> list[Shape]:
    return [Cylinder(x, y, radius, 0.0, height)]
