import itertools

import numpy as np
import pytest

from gmmap.errors import InvalidInputError
from gmmap.mapping.backend import BackendOptions, PoseGraph
from gmmap.mapping.tfgraph import TfGraph
from gmmap.math.geometry import invert, so3_exp


def random_pose(rng: np.random.Generator, scale: float = 5.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = so3_exp(rng.normal(size=(1, 3)))[0]
    T[:3, 3] = rng.normal(0, scale, 3)
    return T


@pytest.fixture
def graph() -> TfGraph:
    """Two groups: {a, b, c, d} with a loop whose edges disagree, and {e, f}; g alone."""
    rng = np.random.default_rng(3)
    g = TfGraph(["g"])
    g.add_edge("a", "b", random_pose(rng), 5)
    g.add_edge("c", "b", random_pose(rng), 3)  # stored as b→c
    g.add_edge("a", "c", random_pose(rng), 1)  # closes a loop, inconsistent on purpose
    g.add_edge("c", "d", random_pose(rng), 2)
    g.add_edge("b", "d", random_pose(rng), 1)  # another loop
    g.add_edge("f", "e", random_pose(rng), 1)
    return g


def test_groups_and_references(graph: TfGraph) -> None:
    assert graph.groups() == [["a", "b", "c", "d"], ["e", "f"], ["g"]]
    assert graph.reference("d") == "a"
    assert graph.reference(["f", "e"]) == "e"
    assert graph.reference("g") == "g"


def test_spanning_tree_has_no_loops_and_maximum_weight(graph: TfGraph) -> None:
    tree = graph.spanning_tree()
    # A forest on 7 robots in 3 components has 4 edges, and adding them never closes a loop.
    assert len(tree) == len(graph.robots) - len(graph.groups())
    parent = {r: r for r in graph.robots}

    def find(r: str) -> str:
        while parent[r] != r:
            r = parent[r]
        return r

    for e in tree:
        ra, rb = find(e.parent), find(e.child)
        assert ra != rb
        parent[rb] = ra
    # Maximum weight: no other spanning forest of the same edges weighs more.
    edges = graph.edges()
    best = 0.0
    for subset in itertools.combinations(edges, len(tree)):
        parent = {r: r for r in graph.robots}
        ok = True
        for e in subset:
            ra, rb = find(e.parent), find(e.child)
            ok &= ra != rb
            parent[rb] = ra
        if ok:
            best = max(best, sum(e.weight for e in subset))
    assert sum(e.weight for e in tree) == best == 5 + 3 + 2 + 1
    # Parents are nearer the reference: the tree hangs from a.
    assert {(e.parent, e.child) for e in tree} == {("a", "b"), ("b", "c"), ("c", "d"), ("e", "f")}


def test_transforms_compose_along_the_tree(graph: TfGraph) -> None:
    for group in graph.groups():
        for a, b, c in itertools.product(group, repeat=3):
            np.testing.assert_allclose(
                graph.transform(a, c), graph.transform(a, b) @ graph.transform(b, c), atol=1e-9
            )
        for a in group:
            np.testing.assert_allclose(graph.transform(a, a), np.eye(4), atol=1e-12)
    # A tree edge is returned as given; the path goes through the tree, never round a loop.
    ab = next(e for e in graph.edges() if (e.parent, e.child) == ("a", "b"))
    np.testing.assert_allclose(graph.transform("a", "b"), ab.transform, atol=1e-12)
    np.testing.assert_allclose(graph.transform("b", "a"), invert(ab.transform), atol=1e-12)
    assert graph.path("a", "d") == ["a", "b", "c", "d"]
    assert graph.path("d", "b") == ["d", "c", "b"]
    T = np.eye(4)
    for p, q in itertools.pairwise(graph.path("d", "a")):
        T = T @ graph.transform(p, q)
    np.testing.assert_allclose(graph.transform("d", "a"), T, atol=1e-9)
    np.testing.assert_allclose(graph.to_reference("d"), graph.transform("a", "d"))


def test_unconnected_and_unknown_robots_raise(graph: TfGraph) -> None:
    with pytest.raises(InvalidInputError, match="not connected"):
        graph.transform("a", "e")
    with pytest.raises(InvalidInputError, match="unknown robot"):
        graph.transform("a", "zz")
    with pytest.raises(InvalidInputError):
        graph.add_edge("a", "a", np.eye(4))
    with pytest.raises(InvalidInputError):
        graph.add_edge("a", "b", np.eye(4), weight=0)


def test_from_backend_result() -> None:
    # Three robots on a line, the true frames known; matches a–b (2) and b–c (1).
    rng = np.random.default_rng(0)
    frames = {"a": np.eye(4), "b": random_pose(rng), "c": random_pose(rng)}
    pg = PoseGraph(BackendOptions(min_matches=1))
    step = np.eye(4)
    step[0, 3] = 1.0
    for r in frames:
        for i in range(4):
            pg.add_submap(r, i, np.linalg.matrix_power(step, i))
    world = {(r, i): frames[r] @ np.linalg.matrix_power(step, i) for r in frames for i in range(4)}

    def match(t, s):
        return pg.add_match(t, s, invert(world[t]) @ world[s])

    match(("a", 1), ("b", 2))
    match(("a", 3), ("b", 0))
    match(("c", 0), ("b", 1))
    result = pg.optimize()
    tf = TfGraph.from_result(result)
    assert tf.groups() == [["a", "b", "c"]]
    assert [(e.parent, e.child, e.weight) for e in tf.spanning_tree()] == [
        ("a", "b", 2.0),
        ("b", "c", 1.0),
    ]
    for r in frames:
        np.testing.assert_allclose(tf.transform("a", r), result.to_reference[r], atol=1e-9)
        np.testing.assert_allclose(tf.transform("a", r), frames[r], atol=1e-6)
    np.testing.assert_allclose(tf.transform("b", "c"), invert(frames["b"]) @ frames["c"], atol=1e-6)
