"""``scan convert`` of a LAS file whose shape says another way up gives the advice ``scan info``,
``decompose`` and ``library build`` give (session 21: it wrote the file as read, silently)."""

from __future__ import annotations

import numpy as np

from arboretum_library.cli import main
from arboretum_library.geometry import zup_to_yup
from arboretum_library.pointio import ReadOptions, read_points
from factories import las_file


def _lying_tree() -> np.ndarray:
    """A toy tree written Y up (N, 3): a trunk 0.2 m wide to 3 m, a ball-shaped crown 3 m wide above."""
    rng = np.random.default_rng(2)
    t, a = rng.uniform(0, 3, 1500), rng.uniform(0, 2 * np.pi, 1500)
    trunk = np.stack([0.1 * np.cos(a), 0.1 * np.sin(a), t], axis=1)
    d = rng.normal(size=(6000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return zup_to_yup(np.concatenate([trunk, d * 1.5 * rng.uniform(0.6, 1.0, (6000, 1)) + [0, 0, 4.5]]))


def test_convert_names_the_up_option_for_a_las_lying_on_its_side(tmp_path, capsys):
    las = las_file(tmp_path / "lying.las", _lying_tree())
    out = tmp_path / "out.ply"
    assert main(["scan", "convert", str(las), str(out)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.endswith("up z; LAS is Z up by its format, so the guess was not applied: pass --up y if the file is not)")
    written = read_points(out, ReadOptions(up="z"))  # as written, no guess
    assert np.ptp(written.points[:, 1]) > 2 * np.ptp(written.points[:, 2])  # written as read: lying on Y

    turned = tmp_path / "turned.ply"
    assert main(["scan", "convert", str(las), str(turned), "--up", "y"]) == 0
    line = capsys.readouterr().out.strip()
    assert "LAS" not in line and line.endswith("up y)")
    upright = read_points(turned, ReadOptions(up="z")).points
    assert np.ptp(upright[:, 2]) > 2 * np.ptp(upright[:, 1])
