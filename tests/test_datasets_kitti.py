import shutil

import numpy as np
import pytest

from gmmap import FileFormatError
from gmmap.io.datasets import Drift, KittiOdometry


@pytest.fixture(scope="module")
def seq00(shared_data):
    return shared_data / "kitti_odometry_mini" / "sequences" / "00"


def test_scans_on_disk_are_the_frames(seq00):
    seq = KittiOdometry(seq00)
    assert seq.format == "kitti"
    assert len(seq) == 10  # poses.txt covers all 4541 scans of the sequence; 10 are present
    times = np.loadtxt(seq00 / "times.txt")
    np.testing.assert_array_equal(seq.stamps, times[:10])
    f = seq[0]
    assert f.points.dtype == np.float32 and f.points.shape[1] == 3
    assert len(f.points) == (seq00 / "velodyne" / "000000.bin").stat().st_size // 16
    assert 110_000 < len(f.points) < 140_000  # an HDL-64 sweep: ~125k points
    raw = np.fromfile(seq00 / "velodyne" / "000000.bin", dtype=np.float32).reshape(-1, 4)
    np.testing.assert_array_equal(f.points, raw[:, :3])


def test_lidar_pose_is_calibration_conjugated_camera_pose(seq00):
    seq = KittiOdometry(seq00)
    # By hand for scan 5: line 6 of poses.txt, the Tr line of the calibration.
    P = np.eye(4)
    P[:3] = np.array((seq00 / "poses.txt").read_text().splitlines()[5].split(), float).reshape(3, 4)
    tr = (seq00 / "calib_Tr_velo_to_cam.txt").read_text().split()
    assert tr[0] == "Tr:"
    Tr = np.eye(4)
    Tr[:3] = np.array(tr[1:13], float).reshape(3, 4)
    expected = np.linalg.inv(Tr) @ P @ Tr
    np.testing.assert_allclose(seq.gt_poses[5], expected, atol=1e-9)
    np.testing.assert_allclose(seq[5].pose, expected, atol=1e-9)
    np.testing.assert_allclose(seq[5].gt_pose, expected, atol=1e-9)
    # In the LiDAR frame the car drives along +x (the camera's +z): ~0.7 m per scan.
    step = seq.gt_poses[9][:3, 3] - seq.gt_poses[8][:3, 3]
    assert step[0] > 0.5 and abs(step[1]) < 0.2 and abs(step[2]) < 0.1


def test_range_voxel_and_drift_options(seq00):
    full = KittiOdometry(seq00)[2].points
    near = KittiOdometry(seq00, min_range=5.0, max_range=20.0)[2].points
    r = np.linalg.norm(near, axis=1)
    assert r.min() >= 5.0 and r.max() <= 20.0 and len(near) < len(full)
    vox = KittiOdometry(seq00, voxel=0.5)[2].points
    assert vox.dtype == np.float32 and 1000 < len(vox) < len(full) / 3
    truth = KittiOdometry(seq00)
    drifted = KittiOdometry(seq00, drift=Drift(seed=1))
    np.testing.assert_array_equal(drifted.gt_poses, truth.gt_poses)
    np.testing.assert_array_equal(drifted.poses[0], truth.poses[0])
    assert not np.allclose(drifted.poses[9], truth.poses[9])


def copy_sequence(src, dst, scans=(0, 1)):
    (dst / "velodyne").mkdir(parents=True)
    for name in ("poses.txt", "times.txt", "calib.txt", "calib_Tr_velo_to_cam.txt"):
        shutil.copy(src / name, dst / name)
    for n in scans:
        shutil.copy(src / "velodyne" / f"{n:06d}.bin", dst / "velodyne" / f"{n:06d}.bin")
    return dst


def test_bad_data_raises_typed_errors_naming_the_file(seq00, tmp_path):
    root = copy_sequence(seq00, tmp_path / "00")
    scan = root / "velodyne" / "000001.bin"
    scan.write_bytes(scan.read_bytes()[:-6])  # cut mid-point
    seq = KittiOdometry(root)
    assert len(seq[0].points) > 100_000
    with pytest.raises(FileFormatError, match=r"000001\.bin: truncated"):
        seq[1]
    (root / "times.txt").write_text("0.0\n")  # one stamp for scans 0 and 1
    with pytest.raises(FileFormatError, match=r"000001\.bin: no entry in times\.txt"):
        KittiOdometry(root)
    (root / "poses.txt").unlink()
    with pytest.raises(FileNotFoundError, match=r"poses\.txt"):
        KittiOdometry(root)
    (root / "calib_Tr_velo_to_cam.txt").unlink()
    shutil.copy(seq00 / "poses.txt", root / "poses.txt")
    with pytest.raises(FileNotFoundError, match=r"calib\.txt"):
        KittiOdometry(root)


def test_official_layout_poses_folder(seq00, tmp_path):
    root = copy_sequence(seq00, tmp_path / "dataset" / "sequences" / "00", scans=(3,))
    (tmp_path / "dataset" / "poses").mkdir()
    (root / "poses.txt").rename(tmp_path / "dataset" / "poses" / "00.txt")
    seq = KittiOdometry(root)
    assert len(seq) == 1
    np.testing.assert_array_equal(seq.gt_poses[0], KittiOdometry(seq00).gt_poses[3])
