import numpy as np
import pytest

from gmmap import FileFormatError
from gmmap.io.datasets.trajectory import associate, read_trajectory, write_trajectory
from gmmap.math.geometry import make_poses


def random_poses(n, seed=0):
    rng = np.random.default_rng(seed)
    return make_poses(rng.uniform(-50, 50, (n, 3)), rng.normal(size=(n, 4)))


def test_write_then_read_trajectory_round_trip(tmp_path):
    stamps = 1_700_000_000.0 + np.sort(np.random.default_rng(1).uniform(0, 100, 200))
    poses = random_poses(200)
    write_trajectory(tmp_path / "t.txt", stamps, poses)
    got_stamps, got_poses = read_trajectory(tmp_path / "t.txt")
    # Stamps are written to the microsecond, the rest to 9 decimals.
    np.testing.assert_allclose(got_stamps, stamps, rtol=0, atol=5e-7)
    np.testing.assert_allclose(got_poses, poses, rtol=0, atol=1e-8)
    assert (tmp_path / "t.txt").read_text().startswith("# timestamp tx ty tz qx qy qz qw\n")


def test_read_trajectory_keeps_line_order_when_asked(tmp_path):
    poses = random_poses(3, seed=2)
    write_trajectory(tmp_path / "t.txt", np.array([3.0, 1.0, 2.0]), poses)
    stamps, by_time = read_trajectory(tmp_path / "t.txt")
    np.testing.assert_array_equal(stamps, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(by_time[0], poses[1], atol=1e-8)
    stamps, by_line = read_trajectory(tmp_path / "t.txt", sort=False)
    np.testing.assert_array_equal(stamps, [3.0, 1.0, 2.0])
    np.testing.assert_allclose(by_line, poses, atol=1e-8)


def test_bad_trajectories_name_the_file(tmp_path):
    (tmp_path / "nan.txt").write_text("0 1 2 nan 0 0 0 1\n")
    with pytest.raises(FileFormatError, match=r"nan\.txt: NaN"):
        read_trajectory(tmp_path / "nan.txt")
    (tmp_path / "empty.txt").write_text("# only a header\n")
    with pytest.raises(FileFormatError, match=r"empty\.txt: no poses"):
        read_trajectory(tmp_path / "empty.txt")


def test_associate_nearest_within_tolerance():
    ref = np.array([0.0, 1.0, 2.0])
    got = associate(np.array([-0.01, 0.49, 0.51, 1.6, 2.015]), ref, 0.5)
    np.testing.assert_array_equal(got, [0, 0, 1, 2, 2])
    np.testing.assert_array_equal(associate(np.array([5.0, 0.1]), np.array([0.0]), 0.2), [-1, 0])
