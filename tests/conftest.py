import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.math.points import voxel_filter

SHARED_DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (real recordings); tests that need it skip on a fresh user machine."""
    if not (SHARED_DATA / "README.md").is_file():
        pytest.skip(f"real recordings not found at {SHARED_DATA} (set GMMAP_SHARED_DATA)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def slice_points() -> np.ndarray:
    """The bundled TUM fr1_xyz slice in the world frame, voxelised at 3 cm."""
    seq = TumRgbd(BUNDLED_TUM_SLICE, stride=2)
    return voxel_filter(np.concatenate([f.world_points() for f in seq]), 0.03)


def known_mixture_samples(n: int, seed: int = 0):
    """Samples of a 3-component mixture with full covariances, and its parameters."""
    rng = np.random.default_rng(seed)
    weights = np.array([0.5, 0.3, 0.2])
    means = np.array([[0.0, 0.0, 0.0], [3.0, 0.5, 1.0], [-1.0, 4.0, -2.0]])
    A = rng.normal(size=(3, 3, 3)) * 0.3
    covs = A @ A.transpose(0, 2, 1) + 0.05 * np.eye(3)
    comp = rng.choice(3, size=n, p=weights)
    z = rng.standard_normal((n, 3))
    pts = means[comp] + np.einsum("nij,nj->ni", np.linalg.cholesky(covs)[comp], z)
    return pts, weights, means, covs


def wait(cond, timeout: float = 15.0) -> bool:
    """Whether ``cond()`` came true within ``timeout`` seconds (polled every 50 ms)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return bool(cond())


def stop_robots(nodes) -> list[tuple[str, str]]:
    """SIGINT to each ``gmmap robot`` process, then their (stdout, stderr) once they end."""
    import signal

    for node in nodes:
        node.send_signal(signal.SIGINT)
    return [node.communicate(timeout=60) for node in nodes]


def assert_two_robots_joined(nodes, outs, folder: Path) -> None:
    """Robots a and b ended cleanly, each holding both robots' two submaps, in one group."""
    import json

    assert [n.returncode for n in nodes] == [0, 0], [err[-1500:] for _, err in outs]
    for name in ("a", "b"):
        r = json.loads((folder / f"{name}.json").read_text())
        assert r["held"] == {"a": 2, "b": 2} and r["groups"] == [["a", "b"]]


def yaw_pose(yaw_deg: float, t) -> np.ndarray:
    """A 4x4 pose turned ``yaw_deg`` about +z and moved by ``t``."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = t
    return T
