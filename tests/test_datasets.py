import numpy as np
import pytest

import gmmap.io.datasets as datasets
from gmmap import FileFormatError
from gmmap.io.datasets import BUNDLED_TUM_SLICE, Drift, TumRgbd
from gmmap.io.datasets.trajectory import write_trajectory
from gmmap.io.datasets.tum import (
    INTRINSICS,
    Intrinsics,
    associate,
    depth_to_points,
    quaternion_to_matrix,
    read_depth,
    read_table,
    read_trajectory,
)


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


def test_fr1_xyz_association_by_hand(shared_data):
    root = shared_data / "tum_fr1_xyz"
    seq = TumRgbd(root, stride=8)
    # 798 depth frames; the motion capture has a gap from 108.8357 to 108.9458 s, so the two
    # depth frames inside it (108.867534, 108.903540) have no pose within 20 ms.
    assert len(seq) == 796
    assert 1305031108.867534 not in seq.stamps and 1305031108.90354 not in seq.stamps
    # Depth 102.160407 lies 4.6 ms after ground-truth line 102.1558 and 5.4 ms before 102.1658:
    # the pose is interpolated 46.07 % of the way from the first to the second.
    assert seq.stamps[0] == 1305031102.160407
    a = (1305031102.160407 - 1305031102.1558) / 0.01
    t0, t1 = np.array([1.3452, 0.6273, 1.6627]), np.array([1.3434, 0.6271, 1.6606])
    np.testing.assert_allclose(seq.gt_poses[0][:3, 3], t0 + a * (t1 - t0), rtol=1e-9)
    R0 = quaternion_to_matrix(np.array([[0.6582, 0.6109, -0.2950, -0.3265]]))[0]
    R1 = quaternion_to_matrix(np.array([[0.6583, 0.6112, -0.2938, -0.3266]]))[0]
    # Between the two samples: the rotation from R0 is `a` of the rotation from R0 to R1.
    angle = lambda R: np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))  # noqa: E731
    assert angle(R0.T @ seq.gt_poses[0][:3, :3]) == pytest.approx(a * angle(R0.T @ R1), rel=1e-3)
    np.testing.assert_array_equal(seq.poses, seq.gt_poses)  # no odometry: pose = ground truth
    assert seq.format == "tum" and seq[-1].stamp == seq.stamps[-1]


def test_bundled_slice_association_and_sequence_protocol():
    seq = TumRgbd(BUNDLED_TUM_SLICE, stride=8)
    listed = [float(r[0]) for r in read_table(BUNDLED_TUM_SLICE / "depth.txt", 2)]
    np.testing.assert_array_equal(seq.stamps, listed)
    gt_stamps, gt_poses = read_trajectory(BUNDLED_TUM_SLICE / "groundtruth.txt")
    for stamp, pose in zip(seq.stamps, seq.gt_poses, strict=True):
        # Interpolated between the samples around the stamp when both are within 20 ms (so
        # within their span), else the nearest sample (beside a gap in the motion capture).
        right = np.searchsorted(gt_stamps, stamp)
        lo, hi = gt_poses[right - 1][:3, 3], gt_poses[right][:3, 3]
        if gt_stamps[right] - stamp <= 0.02 and stamp - gt_stamps[right - 1] <= 0.02:
            assert np.all(pose[:3, 3] >= np.minimum(lo, hi) - 1e-12)
            assert np.all(pose[:3, 3] <= np.maximum(lo, hi) + 1e-12)
        else:
            nearest = np.argmin(np.abs(gt_stamps - stamp))
            assert abs(gt_stamps[nearest] - stamp) <= 0.02
            np.testing.assert_array_equal(pose, gt_poses[nearest])
    frames = list(seq)
    assert len(frames) == len(seq) == 8
    assert seq[-1].stamp == frames[7].stamp and seq[-8].stamp == frames[0].stamp
    assert [f.stamp for f in seq[::3]] == [frames[i].stamp for i in (0, 3, 6)]
    assert seq[np.int64(2)].stamp == frames[2].stamp
    with pytest.raises(IndexError):
        seq[8]
    with pytest.raises(IndexError):
        seq[-9]


def test_back_projection_by_hand():
    K = Intrinsics(fx=500.0, fy=400.0, cx=1.0, cy=0.5)
    depth = np.array([[0, 5000, 10000], [2500, 0, 60000]], dtype=np.uint16)
    pts = depth_to_points(depth, K, depth_factor=5000.0, min_range=0.1, max_range=5.0)
    # Valid pixels in row-major order: (u=1, v=0, z=1 m), (2, 0, 2 m), (0, 1, 0.5 m);
    # 12 m at (2, 1) is beyond max_range. x = (u - cx) z / fx, y = (v - cy) z / fy.
    expected = [
        [0.0, -0.5 / 400, 1.0],
        [1.0 * 2 / 500, -0.5 * 2 / 400, 2.0],
        [-1.0 * 0.5 / 500, 0.5 * 0.5 / 400, 0.5],
    ]
    np.testing.assert_allclose(pts, expected, rtol=1e-6)


def test_back_projected_real_pixel_by_hand():
    seq = TumRgbd(BUNDLED_TUM_SLICE)
    raw = read_depth(seq.files[0])
    v, u = 240, 320
    z = raw[v, u] / 5000.0
    assert 0.1 < z < 5.0
    # freiburg1: fx=517.3 fy=516.5 cx=318.6 cy=255.3
    expected = [(u - 318.6) * z / 517.3, (v - 255.3) * z / 516.5, z]
    pts = seq[0].points
    row = np.flatnonzero((raw.astype(np.float32) / 5000 > 0.1) & (raw / 5000 < 5.0))
    index = int(np.searchsorted(row, v * raw.shape[1] + u))
    np.testing.assert_allclose(pts[index], expected, rtol=1e-5)


def _copy_slice(dst, names=("depth.txt", "groundtruth.txt")):
    for name in names:
        (dst / name).write_text((BUNDLED_TUM_SLICE / name).read_text())
    (dst / "depth").mkdir()
    for png in (BUNDLED_TUM_SLICE / "depth").iterdir():
        (dst / "depth" / png.name).write_bytes(png.read_bytes())


def test_tum_folder_with_odometry_and_intrinsics(tmp_path):
    _copy_slice(tmp_path)
    seq = TumRgbd(BUNDLED_TUM_SLICE)
    offset = np.eye(4)
    offset[:3, 3] = [10.0, -2.0, 0.5]
    odom = offset @ seq.gt_poses  # the robot's own map frame, shifted from the world
    write_trajectory(tmp_path / "odometry.txt", seq.stamps + 0.001, odom)
    (tmp_path / "intrinsics.txt").write_text("600 610 320 240\n")
    sim = TumRgbd(tmp_path)  # the folder name names no camera: intrinsics.txt is used
    assert sim.intrinsics == Intrinsics(600.0, 610.0, 320.0, 240.0)
    assert len(sim) == 8
    np.testing.assert_allclose(sim.poses, odom, atol=1e-8)
    np.testing.assert_array_equal(sim.gt_poses, seq.gt_poses)
    f = sim[3]
    np.testing.assert_allclose(f.pose, odom[3], atol=1e-8)
    np.testing.assert_array_equal(f.gt_pose, seq.gt_poses[3])
    (tmp_path / "groundtruth.txt").unlink()  # odometry alone is enough; no ground truth then
    assert TumRgbd(tmp_path).gt_poses is None and TumRgbd(tmp_path)[0].gt_pose is None


def test_tum_drift_keeps_ground_truth():
    truth = TumRgbd(BUNDLED_TUM_SLICE, stride=8)
    seq = TumRgbd(BUNDLED_TUM_SLICE, stride=8, drift=Drift(translation=0.1, seed=3))
    np.testing.assert_array_equal(seq.gt_poses, truth.gt_poses)
    np.testing.assert_array_equal(seq.poses[0], truth.gt_poses[0])
    assert np.linalg.norm(seq.poses[-1][:3, 3] - truth.gt_poses[-1][:3, 3]) > 1e-3
    np.testing.assert_array_equal(seq[-1].gt_pose, truth.gt_poses[-1])
    np.testing.assert_array_equal(seq[-1].pose, seq.poses[-1])


def test_tum_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"depth\.txt"):
        TumRgbd(tmp_path, intrinsics=Intrinsics(1, 1, 0, 0))
    _copy_slice(tmp_path)
    (tmp_path / "groundtruth.txt").write_text("0.0 1 2 3 0 0 0 1\n")  # far from every frame
    with pytest.raises(FileFormatError, match=r"no frame of depth\.txt has a pose"):
        TumRgbd(tmp_path, intrinsics=Intrinsics(1, 1, 0, 0))
    (tmp_path / "groundtruth.txt").write_text("0.0 1 2 3 0 0\n")
    with pytest.raises(FileFormatError, match=r"groundtruth.txt:1: expected 8 fields"):
        TumRgbd(tmp_path, intrinsics=Intrinsics(1, 1, 0, 0))
    (tmp_path / "groundtruth.txt").unlink()
    with pytest.raises(FileNotFoundError, match=r"groundtruth\.txt"):
        TumRgbd(tmp_path, intrinsics=Intrinsics(1, 1, 0, 0))
    (tmp_path / "sub").mkdir()
    _copy_slice(tmp_path / "sub")  # a fresh folder with an intrinsics.txt that is too short
    (tmp_path / "sub" / "intrinsics.txt").write_text("600 610\n")
    with pytest.raises(FileFormatError, match=r"intrinsics\.txt"):
        TumRgbd(tmp_path / "sub")


def voxel_overlap(a, b, size=0.05):
    """Intersection over union of the voxels two point sets occupy."""
    va, vb = (set(map(tuple, np.floor(p / size).astype(int))) for p in (a, b))
    return len(va & vb) / len(va | vb)


def test_fr3_cabinet_keyframes_pair_frame_i_with_pose_line_i(shared_data):
    root = shared_data / "tum_fr3_cabinet_keyframes"
    seq = datasets.open(root, stride=8)
    assert isinstance(seq, TumRgbd) and seq.match == "order" and len(seq) == 58
    assert seq.intrinsics == INTRINSICS["fr3"]  # from the folder name
    # depth.txt lists depth_imgs/NNNN_depth_raw.png; the folder ships them in depth/.
    assert seq.files[57] == root / "depth" / "0057_depth_raw.png"
    # Line 3 of truth_cam_poses.txt: 1341841280.1825 -2.3319 1.1799 1.1107 (qx qy qz qw) ...
    f = seq[2]
    assert f.stamp == 1341841280.1825
    np.testing.assert_allclose(f.gt_pose[:3, 3], [-2.3319, 1.1799, 1.1107])
    q = np.array([[-0.4077, 0.8121, -0.3749, 0.1837]])
    np.testing.assert_allclose(f.gt_pose[:3, :3], quaternion_to_matrix(q)[0])
    np.testing.assert_array_equal(seq.poses, seq.gt_poses)
    R = seq.gt_poses[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.tile(np.eye(3), (58, 1, 1)), atol=1e-9)
    assert (np.diff(seq.stamps) > 0).all()
    steps = np.linalg.norm(np.diff(seq.gt_poses[:, :3, 3], axis=0), axis=1)
    assert steps.max() < 0.3 and 8.0 < steps.sum() < 8.6  # an 8.3 m loop in keyframe steps
    # Camera→world: neighbouring keyframes see the same surfaces at the same world places.
    a, b = seq[10], seq[11]
    assert voxel_overlap(a.world_points(), b.world_points()) > 0.3
    assert len(seq[57].points) > 1000


def test_keyframe_folder_without_shared_data(tmp_path):
    """The bundled slice rearranged as a keyframe export: numbered frames listed in a folder
    that is not there, and poses by line in truth_cam_poses.txt."""
    _copy_slice(tmp_path, names=())
    truth = TumRgbd(BUNDLED_TUM_SLICE)
    names = [p.name for p in truth.files]
    listed = "".join(f"{i} depth_imgs/{n}\n" for i, n in enumerate(names))
    (tmp_path / "depth.txt").write_text("# timestamp filename\n" + listed)
    write_trajectory(tmp_path / "truth_cam_poses.txt", truth.stamps, truth.gt_poses)
    seq = TumRgbd(tmp_path, intrinsics=truth.intrinsics)
    assert seq.match == "order" and len(seq) == 8
    np.testing.assert_allclose(seq.stamps, truth.stamps, atol=1e-6)
    np.testing.assert_allclose(seq.gt_poses, truth.gt_poses, atol=1e-8)
    np.testing.assert_array_equal(seq[5].points, truth[5].points)
    (tmp_path / "depth.txt").write_text(listed + f"8 depth_imgs/{names[0]}\n")
    with pytest.raises(FileFormatError, match=r"truth_cam_poses\.txt: 8 poses for 9 frames"):
        TumRgbd(tmp_path, intrinsics=truth.intrinsics)
