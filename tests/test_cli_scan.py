"""``arboretum scan info`` and ``arboretum scan convert`` through ``cli.main``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arboretum_library.cli import main
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import ReadOptions, read_points, write_points

COUNTS = {
    "01_rtwig_coffeetree.xyz": 14_667,
    "06_adtree_tree7.xyz": 15_130,
    "07_itsme_buttressed_tree_1.xyz": 64_082,
    "10_treels_pine.xyz": 73_851,
    "pine.laz": 73_851,
}


@pytest.fixture(scope="module")
def scans(scans_dir) -> list:
    files = sorted(scans_dir.glob("*/*.xyz")) + [scans_dir / "10_treels_pine" / "pine.laz"]
    assert sorted(f.name for f in files) == sorted(COUNTS)
    return files


def test_info_json_on_every_bundled_scan(scans, capsys):
    assert main(["scan", "info", *map(str, scans), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [o["file"] for o in out] == [str(f) for f in scans]
    for o in out:
        name = o["file"].rsplit("/", 1)[-1]
        assert o["points"] == COUNTS[name], name
        assert (o["up_axis"], o["up_guess"]) == ("z", "z") and o["up_confidence"] > 0.9
        assert o["height"] == pytest.approx(o["size"][2]) and o["height"] > 3.0
        assert 0.005 < o["spacing"] < 0.05
        assert not (o["has_colors"] or o["has_labels"] or o["has_branch_ids"])
    pine = [o for o in out if o["file"].endswith("pine.laz")][0]
    assert pine["height"] == pytest.approx(20.16, abs=1e-3)


def test_info_text(scans, capsys):
    assert main(["scan", "info", str(scans[0])]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == str(scans[0])
    assert "  points     14,667" in out
    assert "  height     3.704 m" in out
    assert any(line.startswith("  up axis    z (guess z, confidence") for line in out)


def test_info_y_up_file(tmp_path, scans, capsys):
    pts = read_points(scans[1], ReadOptions(up="z")).points
    path = write_points(tmp_path / "yup.ply", zup_to_yup(pts))
    assert main(["scan", "info", str(path), "--json"]) == 0
    auto = json.loads(capsys.readouterr().out)[0]
    assert (auto["up_axis"], auto["up_guess"]) == ("y", "y")
    assert auto["height"] == pytest.approx(np.ptp(pts[:, 2]))
    assert main(["scan", "info", str(path), "--up", "z", "--json"]) == 0
    forced = json.loads(capsys.readouterr().out)[0]
    assert forced["up_axis"] == "z" and forced["height"] == pytest.approx(np.ptp(pts[:, 1]))


@pytest.mark.parametrize(
    "content, problem",
    [(None, "no such file"), (b"1 2 3\n", "exactly one point"), (b"1 2\n3 4\n", "at least 3")],
)
def test_info_bad_file_exit_2_one_line(tmp_path, capsys, scans, content, problem):
    bad = tmp_path / "bad.xyz"
    if content is not None:
        bad.write_bytes(content)
    assert main(["scan", "info", str(scans[0]), str(bad)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and problem in lines[0]
    assert lines[0].startswith("arboretum scan: error: ") and "Traceback" not in captured.err


def test_info_unknown_extension(tmp_path, capsys):
    (tmp_path / "tree.obj").write_text("v 0 0 0\n")
    assert main(["scan", "info", str(tmp_path / "tree.obj")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert (
        len(err) == 1 and "supported: .asc .csv .las .laz .npy .pcd .ply .pts .txt .xyz" in err[0]
    )


def test_convert_prepares_like_vrtree(tmp_path, scans, capsys):
    out = tmp_path / "pine.ply"
    args = [
        "scan",
        "convert",
        str(scans[-1]),
        str(out),
        "--recentre",
        "--height",
        "0.8",
        "--max-points",
        "12000",
    ]
    assert main([*args, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == 12_000 and summary["file"] == str(out)
    cloud = read_points(out, ReadOptions(up="z"))
    assert len(cloud) == 12_000
    assert np.ptp(cloud.points[:, 2]) == pytest.approx(0.8, abs=1e-9)
    assert cloud.points[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    assert main(args) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: 12,000 points, height 0.800 m")
    np.testing.assert_array_equal(read_points(out, ReadOptions(up="z")).points, cloud.points)


def test_convert_bad_arguments(tmp_path, scans, capsys):
    assert main(["scan", "convert", str(scans[0]), str(tmp_path / "out.obj")]) == 2
    assert "writable: .npy .ply .txt .xyz" in capsys.readouterr().err
    assert main(["scan", "convert", str(scans[0]), str(tmp_path / "o.ply"), "--height", "-1"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "target height must be a number > 0" in err[0]
    assert not list(tmp_path.iterdir())
