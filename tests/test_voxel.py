import numpy as np
import pytest

from gmmap import InvalidInputError, voxel_filter


def reference_voxel_filter(points, size):
    keys = np.floor(points / size).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(first), 3))
    np.add.at(sums, inverse, points)
    counts = np.bincount(inverse)
    return (sums / counts[:, None])[np.argsort(first)]


def test_matches_reference_centroids_in_first_seen_order():
    pts = np.random.default_rng(0).uniform(-2, 2, (20_000, 3))
    np.testing.assert_allclose(
        voxel_filter(pts, 0.25), reference_voxel_filter(pts, 0.25), rtol=1e-12, atol=1e-12
    )


def test_one_point_per_voxel(slice_points):
    out = voxel_filter(slice_points, 0.1)
    keys = np.floor(out / 0.1).astype(np.int64)
    assert len(np.unique(keys, axis=0)) == len(out) < len(slice_points)


def test_edge_cases():
    assert voxel_filter(np.zeros((0, 3)), 0.1).shape == (0, 3)
    with pytest.raises(InvalidInputError, match="voxel_size"):
        voxel_filter(np.zeros((3, 3)), 0.0)
    with pytest.raises(InvalidInputError, match="NaN"):
        voxel_filter([[0, 0, np.nan]], 0.1)
    with pytest.raises(InvalidInputError, match="too large"):
        voxel_filter([[1e300, 0, 0]], 1e-3)
