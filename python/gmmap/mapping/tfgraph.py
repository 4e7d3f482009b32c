"""TF graph: robots' map frames as nodes, relative transforms between them as edges.

Convention (tf2's lookupTransform(target, source), and `register`'s source → target):
``transform(a, b)`` is the 4x4 T_a←b that maps coordinates in robot b's map frame into robot
a's, so ``transform(a, b) @ transform(b, c) == transform(a, c)`` and an edge added as
``add_edge(a, b, T)`` means the same T_a←b.

Queries compose along a maximum-weight spanning forest (Kruskal; weight = e.g. the number of
accepted matches between the two robots). The path between two robots in that tree is the one
whose weakest edge is strongest, and because it is a tree no query ever goes round a loop:
edges that would close one (and may disagree with the tree) are ignored. Each connected
component is a group; its reference is its lowest robot name, the frame `PoseGraph` optimises
in. Transforms are composed once from each reference down the tree (T_ref←r), so a query is
T_ref←a⁻¹·T_ref←b: the same product as along the path, with the shared part cancelling.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.mapping.backend import BackendResult
from gmmap.math.geometry import invert, project_rigid


@dataclass(frozen=True)
class TfEdge:
    """``transform`` maps ``child``'s frame into ``parent``'s (T_parent←child)."""

    parent: str
    child: str
    transform: np.ndarray
    weight: float


class TfGraph:
    """Robots' map frames and the transforms between them; see the module docstring."""

    def __init__(self, robots: Iterable[str] = ()) -> None:
        self._robots: set[str] = set()
        self._edges: dict[tuple[str, str], TfEdge] = {}  # key: (lower name, higher name)
        self._tree: dict[str, tuple[str, np.ndarray, list[str]]] | None = None
        for r in robots:
            self.add_robot(r)

    @classmethod
    def from_result(cls, result: BackendResult) -> TfGraph:
        """Edges between robots with accepted matches, weighted by their count, each the
        optimised relative frame to_reference(a)⁻¹·to_reference(b)."""
        graph = cls(result.to_reference)
        counts: dict[tuple[str, str], int] = {}
        for edge_id in result.accepted:
            (a, _), (b, _) = result.edges[edge_id]
            if a != b:
                key = (min(a, b), max(a, b))
                counts[key] = counts.get(key, 0) + 1
        for (a, b), n in sorted(counts.items()):
            T = invert(result.to_reference[a]) @ result.to_reference[b]
            graph.add_edge(a, b, T, float(n))
        return graph

    # ---------------------------------------------------------------------------- build
    def add_robot(self, robot: str) -> None:
        self._robots.add(str(robot))
        self._tree = None

    def add_edge(self, a: str, b: str, transform: np.ndarray, weight: float = 1.0) -> None:
        """Adds (or replaces) the edge between a and b; ``transform`` maps b's frame into a's."""
        a, b = str(a), str(b)
        if a == b:
            raise InvalidInputError(f"an edge from {a!r} to itself")
        T = np.asarray(transform, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InvalidInputError(f"transform must be a finite 4x4 matrix, got {T.shape}")
        if not (np.isfinite(weight) and weight > 0):
            raise InvalidInputError(f"weight must be finite and > 0, got {weight}")
        T = project_rigid(T)
        if a > b:  # stored once, from the lower name
            a, b, T = b, a, invert(T)
        self._robots |= {a, b}
        self._edges[(a, b)] = TfEdge(a, b, T, float(weight))
        self._tree = None

    # -------------------------------------------------------------------------- queries
    @property
    def robots(self) -> list[str]:
        return sorted(self._robots)

    def edges(self) -> list[TfEdge]:
        """All edges (parent = the lower name), sorted."""
        return [self._edges[k] for k in sorted(self._edges)]

    def groups(self) -> list[list[str]]:
        """Connected components, each sorted, sorted by their first (reference) robot."""
        tree = self._spanning()
        groups: dict[str, list[str]] = {}
        for r in self.robots:
            groups.setdefault(tree[r][2][0], []).append(r)
        return sorted(groups.values())

    def reference(self, robot_or_group: str | Iterable[str]) -> str:
        """The reference robot (lowest name) of a robot's group, or of a group given as names."""
        if isinstance(robot_or_group, str):
            self._check(robot_or_group)
            return self._spanning()[robot_or_group][2][0]
        names = sorted(robot_or_group)
        if not names:
            raise InvalidInputError("an empty group has no reference")
        return names[0]

    def spanning_tree(self) -> list[TfEdge]:
        """The maximum-weight spanning forest, each edge from the robot nearer its group's
        reference (parent) to the farther (child); sorted by (parent, child)."""
        tree = self._spanning()
        out = []
        for child, (parent, _, _) in tree.items():
            if parent != child:
                a, b = min(parent, child), max(parent, child)
                e = self._edges[(a, b)]
                T = e.transform if parent == a else invert(e.transform)
                out.append(TfEdge(parent, child, T, e.weight))
        return sorted(out, key=lambda e: (e.parent, e.child))

    def path(self, a: str, b: str) -> list[str]:
        """The robots from a to b along the spanning tree (both included)."""
        self._same_group(a, b)
        up_a, up_b = self._ancestry(a), self._ancestry(b)
        common = next(r for r in up_a if r in set(up_b))
        return up_a[: up_a.index(common) + 1] + up_b[: up_b.index(common)][::-1]

    def transform(self, a: str, b: str) -> np.ndarray:
        """T_a←b (4x4): maps coordinates in b's map frame into a's, along the spanning tree.
        Raises InvalidInputError when a and b are not connected."""
        self._same_group(a, b)
        tree = self._spanning()
        return invert(tree[a][1]) @ tree[b][1]

    def to_reference(self, robot: str) -> np.ndarray:
        """T_ref←robot for the reference of the robot's group."""
        return self.transform(self.reference(robot), robot)

    # ------------------------------------------------------------------------ internals
    def _check(self, robot: str) -> None:
        if robot not in self._robots:
            raise InvalidInputError(f"unknown robot {robot!r}; known: {self.robots}")

    def _same_group(self, a: str, b: str) -> None:
        self._check(a)
        self._check(b)
        tree = self._spanning()
        if tree[a][2][0] != tree[b][2][0]:
            raise InvalidInputError(f"robots {a!r} and {b!r} are not connected")

    def _ancestry(self, robot: str) -> list[str]:
        tree = self._spanning()
        out = [robot]
        while tree[out[-1]][0] != out[-1]:
            out.append(tree[out[-1]][0])
        return out

    def _spanning(self) -> dict[str, tuple[str, np.ndarray, list[str]]]:
        """Per robot: (parent, T_ref←robot, [reference]), built once per change: Kruskal on
        the edges by decreasing weight (ties by name, so the tree is deterministic), then a
        breadth-first walk from each component's lowest name."""
        if self._tree is not None:
            return self._tree
        parent = {r: r for r in self._robots}

        def find(r: str) -> str:
            while parent[r] != r:
                parent[r] = parent[parent[r]]
                r = parent[r]
            return r

        adjacent: dict[str, list[tuple[str, np.ndarray]]] = {r: [] for r in self._robots}
        for (a, b), e in sorted(self._edges.items(), key=lambda kv: (-kv[1].weight, kv[0])):
            ra, rb = find(a), find(b)
            if ra == rb:
                continue  # would close a loop
            parent[max(ra, rb)] = min(ra, rb)
            adjacent[a].append((b, e.transform))
            adjacent[b].append((a, invert(e.transform)))
        tree: dict[str, tuple[str, np.ndarray, list[str]]] = {}
        for root in sorted(self._robots):
            if root in tree:
                continue
            ref = [root]  # shared by the whole group
            tree[root] = (root, np.eye(4), ref)
            queue = [root]
            while queue:
                r = queue.pop(0)
                for nxt, T_r_nxt in sorted(adjacent[r], key=lambda x: x[0]):
                    if nxt not in tree:
                        tree[nxt] = (r, tree[r][1] @ T_r_nxt, ref)
                        queue.append(nxt)
        self._tree = tree
        return tree
