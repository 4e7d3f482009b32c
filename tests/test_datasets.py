import numpy as np
import pytest

from gmmap import FileFormatError
from gmmap.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.datasets.tum import associate, quaternion_to_matrix


def test_bundled_slice_loads_with_ground_truth():
    seq = TumRgbd(BUNDLED_TUM_SLICE, stride=4)
    assert len(seq) == 8
    f = seq[0]
    assert f.points.dtype == np.float32 and f.points.shape[1] == 3
    assert 5_000 < len(f.points) <= 640 * 480 // 16
    assert f.points[:, 2].min() > 0.1 and f.points[:, 2].max() < 5.0
    R = f.pose[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert len(seq[2:5]) == 3


def test_quaternion_and_association():
    np.testing.assert_allclose(quaternion_to_matrix(np.array([[0, 0, 0, 1.0]]))[0], np.eye(3))
    Rz = quaternion_to_matrix(np.array([[0, 0, np.sin(0.5), np.cos(0.5)]]))[0]
    np.testing.assert_allclose(Rz[:2, :2], [[np.cos(1), -np.sin(1)], [np.sin(1), np.cos(1)]])
    ref = np.array([0.0, 1.0, 2.0])
    np.testing.assert_array_equal(associate(np.array([0.01, 1.6, 2.5]), ref, 0.02), [0, -1, -1])


def test_corrupt_depth_image_names_the_file(tmp_path):
    for name in ("depth.txt", "groundtruth.txt"):
        (tmp_path / name).write_text((BUNDLED_TUM_SLICE / name).read_text())
    (tmp_path / "depth").mkdir()
    first = next(iter(sorted((BUNDLED_TUM_SLICE / "depth").iterdir())))
    (tmp_path / "depth" / first.name).write_bytes(first.read_bytes()[:500])
    seq = TumRgbd(tmp_path, intrinsics=TumRgbd(BUNDLED_TUM_SLICE).intrinsics)
    with pytest.raises(FileFormatError, match=first.name):
        seq[0]
    with pytest.raises(FileNotFoundError, match="missing depth image"):
        seq[1]


def test_full_fr1_xyz_recording(shared_data):
    seq = TumRgbd(shared_data / "tum_fr1_xyz", stride=8)
    assert len(seq) > 780
    path = np.linalg.norm(np.diff([f[:3, 3] for f in seq.gt_poses], axis=0), axis=1).sum()
    assert 5.0 < path < 10.0  # fr1_xyz: about 7 m of hand-held motion
    assert len(seq[len(seq) - 1].points) > 1000
