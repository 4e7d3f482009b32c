import json

import numpy as np
import pytest
from click.testing import CliRunner

import gmmap.io.datasets as datasets
from gmmap import FileFormatError, InvalidInputError
from gmmap.cli import main
from gmmap.errors import UnknownFormatError
from gmmap.io.datasets import BUNDLED_TUM_SLICE, KittiOdometry, PointFiles, TumRgbd

INFO_KEYS = {"format", "frames", "duration_s", "path_length_m", "points_per_frame"}


def info(*args):
    result = CliRunner().invoke(main, ["info", *map(str, args)], catch_exceptions=False)
    return result


def test_open_detects_tum_and_passes_options():
    seq = datasets.open(BUNDLED_TUM_SLICE, stride=4)
    assert isinstance(seq, TumRgbd) and seq.format == "tum" and len(seq) == 8
    assert seq.options["stride"] == 4
    with pytest.raises(InvalidInputError, match=r"takes no option topic.*stride"):
        datasets.open(BUNDLED_TUM_SLICE, topic="/points")
    with pytest.raises(InvalidInputError, match="unknown format 'las'"):
        datasets.open(BUNDLED_TUM_SLICE, format="las")


def test_open_detects_kitti(shared_data):
    seq = datasets.open(shared_data / "kitti_odometry_mini" / "sequences" / "08", voxel=1.0)
    assert isinstance(seq, KittiOdometry) and seq.format == "kitti" and len(seq) == 10


def test_open_detects_point_files_and_rejects_the_unknown(tmp_path):
    (tmp_path / "0.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n1 2 3\n"
    )
    (tmp_path / "poses.txt").write_text("0.0 0 0 0 0 0 0 1\n")
    seq = datasets.open(tmp_path)
    assert isinstance(seq, PointFiles) and seq.format == "pointfiles"
    np.testing.assert_array_equal(seq[0].points, [[1, 2, 3]])
    (tmp_path / "0.ply").unlink()
    with pytest.raises(UnknownFormatError, match=r"tum .*kitti .*pointfiles .*rosbag") as err:
        datasets.open(tmp_path)
    assert isinstance(err.value, FileFormatError)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        datasets.open(tmp_path / "nowhere")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(UnknownFormatError):
        datasets.open(tmp_path / "notes.txt")


def test_info_json_on_the_bundled_slice():
    result = info(BUNDLED_TUM_SLICE, "--json", "--stride", "4")
    assert result.exit_code == 0, result.output
    r = json.loads(result.stdout)
    assert set(r) >= INFO_KEYS
    assert r["format"] == "tum" and r["frames"] == 8
    seq = TumRgbd(BUNDLED_TUM_SLICE, stride=4)
    assert r["duration_s"] == pytest.approx(seq.stamps[-1] - seq.stamps[0])
    steps = np.diff(seq.gt_poses[:, :3, 3], axis=0)
    assert r["path_length_m"] == pytest.approx(np.linalg.norm(steps, axis=1).sum())
    assert r["points_per_frame"] == pytest.approx(np.mean([len(f.points) for f in seq]))
    assert "points_per_frame_sampled" not in r
    sampled = json.loads(info(BUNDLED_TUM_SLICE, "--json", "--stride", "8", "--sample", "3").stdout)
    assert sampled["points_per_frame_sampled"] == 3
    text = info(BUNDLED_TUM_SLICE, "--stride", "8").stdout
    assert "frames          8" in text and "tum" in text


def test_info_json_on_kitti(shared_data):
    r = json.loads(info(shared_data / "kitti_odometry_mini/sequences/00", "--json").stdout)
    assert set(r) >= INFO_KEYS
    assert r["format"] == "kitti" and r["frames"] == 10
    assert r["duration_s"] == pytest.approx(0.9331467)
    assert 5.0 < r["path_length_m"] < 8.0  # ten scans at ~7 m/s
    assert 110_000 < r["points_per_frame"] < 140_000


def test_info_json_on_fr3_cabinet_keyframes(shared_data):
    root = shared_data / "tum_fr3_cabinet_keyframes"
    result = info(root, "--json", "--stride", "8", "--sample", "5")
    assert result.exit_code == 0, result.output
    r = json.loads(result.stdout)
    assert set(r) >= INFO_KEYS
    assert r["format"] == "tum" and r["frames"] == 58
    assert r["duration_s"] == pytest.approx(38.4079, abs=1e-3)  # the pose stamps' span
    assert r["path_length_m"] == pytest.approx(8.27, abs=0.01)  # the data README: an 8.3 m loop
    assert r["gt_path_length_m"] == r["path_length_m"]
    assert r["points_per_frame_sampled"] == 5 and r["points_per_frame"] > 1000


def test_info_reports_bad_data_in_one_line(tmp_path):
    result = info(tmp_path)
    assert result.exit_code != 0
    assert "not a dataset gmmap can read" in result.output and "Traceback" not in result.output
