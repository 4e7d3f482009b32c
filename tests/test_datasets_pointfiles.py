import numpy as np
import pytest

from gmmap import FileFormatError
from gmmap.io.datasets import Drift, PointFiles
from gmmap.io.datasets.pcd import read_pcd
from gmmap.io.datasets.ply import read_ply
from gmmap.io.datasets.ply import write_ply as write_ply_file


def cloud(n: int = 200, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-5, 5, (n, 3)).astype(np.float32)


def write_ply(path, pts, fmt="ascii", coord="float"):
    """x y z, an intensity and a colour per vertex, then a face element (to be skipped)."""
    n = len(pts)
    head = (
        f"ply\nformat {fmt} 1.0\ncomment written by the test\nelement vertex {n}\n"
        f"property {coord} x\nproperty {coord} y\nproperty {coord} z\n"
        "property float intensity\nproperty uchar red\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    if fmt == "ascii":
        rows = "".join(
            f"{x!r} {y!r} {z!r} 0.5 {i % 256}\n" for i, (x, y, z) in enumerate(pts.tolist())
        )
        path.write_bytes((head + rows + "3 0 1 2\n").encode())
        return
    order = "<" if fmt == "binary_little_endian" else ">"
    t = "f4" if coord == "float" else "f8"
    dtype = np.dtype([(a, order + t) for a in "xyz"] + [("i", order + "f4"), ("r", "u1")])
    rows = np.zeros(n, dtype)
    for k, a in enumerate("xyz"):
        rows[a] = pts[:, k]
    rows["r"] = np.arange(n) % 256
    face = np.array([3], "u1").tobytes() + np.array([0, 1, 2], order + "i4").tobytes()
    path.write_bytes(head.encode() + rows.tobytes() + face)


def write_pcd(path, pts, data="ascii"):
    """x y z, a padding field, an rgb (U4) and a 2-count normal field, as PCL writes them."""
    n = len(pts)
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        "FIELDS x y z _ rgb normal\nSIZE 4 4 4 1 4 4\nTYPE F F F U U F\nCOUNT 1 1 1 4 1 2\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
    if data == "ascii":
        rows = "".join(f"{x!r} {y!r} {z!r} 0 0 0 0 255 0.1 0.2\n" for x, y, z in pts.tolist())
        path.write_bytes((head + rows).encode())
        return
    dtype = np.dtype(
        [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_", "u1", 4), ("rgb", "<u4"), ("n", "<f4", 2)]
    )
    rows = np.zeros(n, dtype)
    for k, a in enumerate("xyz"):
        rows[a] = pts[:, k]
    path.write_bytes(head.encode() + rows.tobytes())


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("coord", ["float", "double"])
def test_ply_round_trip(tmp_path, fmt, coord):
    pts = cloud()
    write_ply(tmp_path / "a.ply", pts, fmt, coord)
    got = read_ply(tmp_path / "a.ply")
    assert got.dtype == np.float32 and got.shape == pts.shape
    np.testing.assert_array_equal(got, pts)


@pytest.mark.parametrize("data", ["ascii", "binary"])
def test_pcd_round_trip_drops_nan_points(tmp_path, data):
    pts = cloud()
    pts[7] = np.nan  # PCL marks missing returns of organised clouds with NaN
    write_pcd(tmp_path / "a.pcd", pts, data)
    got = read_pcd(tmp_path / "a.pcd")
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, np.delete(pts, 7, axis=0))


def test_truncated_and_unsupported_files_name_the_file(tmp_path):
    pts = cloud()
    for name, write in [
        ("b.ply", lambda p: write_ply(p, pts, "binary_little_endian")),
        ("a.ply", lambda p: write_ply(p, pts, "ascii")),
        ("b.pcd", lambda p: write_pcd(p, pts, "binary")),
        ("a.pcd", lambda p: write_pcd(p, pts, "ascii")),
    ]:
        path = tmp_path / name
        write(path)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
        reader = read_ply if name.endswith("ply") else read_pcd
        with pytest.raises(FileFormatError, match=rf"{name}: truncated"):
            reader(path)
    (tmp_path / "c.pcd").write_bytes(
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"
        b"COUNT 1 1 1\nWIDTH 1\nPOINTS 1\nDATA binary_compressed\n"
    )
    with pytest.raises(FileFormatError, match=r"c\.pcd: DATA binary_compressed is unsupported"):
        read_pcd(tmp_path / "c.pcd")
    (tmp_path / "d.ply").write_bytes(b"not a ply at all")
    with pytest.raises(FileFormatError, match=r"d\.ply: not a PLY file"):
        read_ply(tmp_path / "d.ply")
    with pytest.raises(FileNotFoundError, match=r"e\.pcd"):
        read_pcd(tmp_path / "e.pcd")


def poses_along_x(stamps):
    """TUM lines: the sensor 1 m further along x at each stamp, turned about z."""
    return "".join(
        f"{s:.6f} {i:.1f} 0 0 0 0 {np.sin(0.05 * i):.9f} {np.cos(0.05 * i):.9f}\n"
        for i, s in enumerate(stamps)
    )


def test_folder_by_stamp(tmp_path):
    stamps = [100.0, 100.1, 100.2, 100.3]
    for k, s in enumerate(stamps):
        write_pcd(tmp_path / f"{s:.6f}.pcd", cloud(seed=k), "binary")
    # The poses are denser than the frames and offset by 5 ms: association by nearest stamp.
    dense = np.arange(99.9, 100.45, 0.05) + 0.005
    (tmp_path / "poses.txt").write_text("# stamp tx ty tz qx qy qz qw\n" + poses_along_x(dense))
    seq = PointFiles(tmp_path)
    assert seq.format == "pointfiles" and seq.match == "stamp" and len(seq) == 4
    np.testing.assert_allclose(seq.stamps, stamps)
    # 100.1 is nearest 100.105 (line 4, x = 4.0)
    np.testing.assert_allclose(seq[1].pose[:3, 3], [4.0, 0, 0])
    np.testing.assert_array_equal(seq[-1].points, cloud(seed=3))
    assert seq[0].gt_pose is None
    with pytest.raises(FileFormatError, match="have no pose"):
        PointFiles(tmp_path, match="stamp", max_dt=0.001)


def test_folder_by_line_order_and_options(tmp_path):
    for k in range(3):
        write_ply(tmp_path / f"scan_{k:02d}.ply", cloud(seed=k), "binary_little_endian")
    (tmp_path / "trajectory.txt").write_text(poses_along_x([5.0, 6.0, 7.0]))
    seq = PointFiles(tmp_path, min_range=1.0, max_range=6.0)
    assert seq.match == "order" and len(seq) == 3
    np.testing.assert_array_equal(seq.stamps, [5.0, 6.0, 7.0])
    np.testing.assert_allclose(seq[2].pose[:3, 3], [2.0, 0, 0])
    r = np.linalg.norm(seq[0].points, axis=1)
    assert r.min() >= 1.0 and r.max() <= 6.0
    drifted = PointFiles(tmp_path, drift=Drift(translation=0.5, seed=4))
    np.testing.assert_allclose(drifted.gt_poses, seq.poses)
    assert not np.allclose(drifted.poses[2], seq.poses[2])
    (tmp_path / "trajectory.txt").write_text(poses_along_x([5.0, 6.0]))
    with pytest.raises(FileFormatError, match="2 poses for 3 point files"):
        PointFiles(tmp_path)
    (tmp_path / "trajectory.txt").unlink()
    with pytest.raises(FileNotFoundError, match=r"poses\.txt"):
        PointFiles(tmp_path)


def test_folder_with_odometry_and_ground_truth(tmp_path):
    stamps = [100.0, 100.2, 100.4]
    for k, s in enumerate(stamps):
        write_ply_file(tmp_path / f"{s:.6f}.ply", cloud(seed=k))
    (tmp_path / "poses.txt").write_text(poses_along_x(stamps))
    # The truth: twice as far along x, and sampled more densely than the scans.
    truth = "".join(f"{s:.6f} {2 * i:.1f} 0 0 0 0 0 1\n" for i, s in enumerate(stamps))
    (tmp_path / "groundtruth.txt").write_text(truth + "100.5 9 9 9 0 0 0 1\n")
    seq = PointFiles(tmp_path)
    assert seq.match == "stamp" and seq.gt_path == tmp_path / "groundtruth.txt"
    np.testing.assert_allclose(seq[2].pose[:3, 3], [2.0, 0, 0])
    np.testing.assert_allclose(seq[2].gt_pose[:3, 3], [4.0, 0, 0])
    np.testing.assert_array_equal(seq[1].points, cloud(seed=1))
    # Drift moves the odometry only; the ground truth stays the file's.
    drifted = PointFiles(tmp_path, drift=Drift(translation=0.5, seed=1))
    np.testing.assert_array_equal(drifted.gt_poses, seq.gt_poses)
    # groundtruth.txt as the poses file leaves no second file for the truth.
    assert PointFiles(tmp_path, poses="groundtruth.txt").gt_poses is None
    (tmp_path / "truth_by_line.txt").write_text(truth)
    by_line = PointFiles(tmp_path, groundtruth="truth_by_line.txt", match="order")
    np.testing.assert_allclose(by_line.gt_poses, seq.gt_poses)
    with pytest.raises(FileFormatError, match=r"groundtruth\.txt: 4 poses for 3 point files"):
        PointFiles(tmp_path, match="order")
    with pytest.raises(FileNotFoundError, match=r"nowhere\.txt: missing ground-truth file"):
        PointFiles(tmp_path, groundtruth="nowhere.txt")


def test_ply_elements_before_the_vertices(tmp_path):
    pts = cloud(5)
    head = "ply\nformat {} 1.0\nelement camera 2\nproperty float k\nproperty uchar id\n{}"
    vertex = (
        "element vertex 5\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
    )
    # Binary: a scalar-only element first is skipped by its size (2 × 5 bytes).
    camera = np.zeros(2, [("k", "<f4"), ("id", "u1")]).tobytes()
    body = pts.astype("<f8").tobytes()
    path = tmp_path / "b.ply"
    path.write_bytes(head.format("binary_little_endian", vertex).encode() + camera + body)
    np.testing.assert_array_equal(read_ply(path), pts)
    # ASCII: any element first, lists included, is one line per row.
    text = head.replace("property uchar id", "property list uchar int id").format("ascii", vertex)
    rows = "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in pts.astype(np.float64).tolist())
    (tmp_path / "a.ply").write_text(text + "1.5 2 7 8\n2.5 0\n" + rows)
    np.testing.assert_array_equal(read_ply(tmp_path / "a.ply"), pts)
    # Binary with a list element first: skipping it would mean parsing every list.
    (tmp_path / "c.ply").write_bytes(text.replace("ascii", "binary_little_endian").encode())
    with pytest.raises(FileFormatError, match=r"c\.ply: binary element 'camera' has list"):
        read_ply(tmp_path / "c.ply")
    (tmp_path / "d.ply").write_text(text.replace("double z", "double w") + "\n")
    with pytest.raises(FileFormatError, match=r"d\.ply: vertex has no z"):
        read_ply(tmp_path / "d.ply")
