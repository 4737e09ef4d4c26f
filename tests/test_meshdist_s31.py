"""Point-to-mesh distances in numpy (session 31): the buried-lobe repair measures depths without open3d."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from arboretum_server.decompose.meshdist import BLOCK, surface_distances


def test_each_region_of_a_triangle_gives_its_distance():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    q = np.array([[0.2, 0.2, 0.5],    # over the face: its height
                  [-1.0, -1, 0],      # beyond vertex a
                  [2.0, 0, 0],        # beyond vertex b
                  [0.0, 3, 1],        # beyond vertex c
                  [0.5, -2, 0],       # beyond edge ab
                  [-2.0, 0.5, 0],     # beyond edge ac
                  [1.0, 1, 0]])       # beyond edge bc
    expected = [0.5, np.sqrt(2), 1.0, np.sqrt(5), 2.0, 2.0, np.sqrt(0.5)]
    np.testing.assert_allclose(surface_distances(v, f, q), expected, atol=1e-12)


def test_a_closed_hull_matches_open3ds_ray_casting():
    from scipy.spatial import ConvexHull

    from arboretum_server.decompose.evaluate import signed_distances

    rng = np.random.default_rng(3)
    pts = rng.normal(size=(60, 3))
    hull = ConvexHull(pts)
    v, f = pts, hull.simplices
    q = rng.uniform(-3, 3, size=(2 * BLOCK + 17, 3))  # several blocks, one partial
    np.testing.assert_allclose(surface_distances(v, f, q), np.abs(signed_distances(v, f, q)), atol=1e-6)


def test_a_triangle_of_no_area_counts_by_its_edges_and_no_triangles_is_inf():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    d = surface_distances(v, np.array([[0, 1, 2]]), np.array([[1.0, 1, 0], [3.0, 0, 0]]))
    np.testing.assert_allclose(d, [1.0, 1.0])
    assert np.isinf(surface_distances(v, np.zeros((0, 3), int), np.zeros((2, 3)))).all()


def test_the_depths_of_a_buried_lobe_import_no_open3d():
    # open3d's import took 2.1 s here: the first buried-lobe insert of a service stalled that long
    code = (
        "import sys, numpy as np\n"
        "from scipy.spatial import ConvexHull\n"
        "from arboretum_server.decompose.state import LobeState\n"
        "from arboretum_server.decompose.tunnel import depths\n"
        "def lobe(r):\n"
        "    p = np.random.default_rng(0).normal(size=(40, 3)) * r\n"
        "    p = p[ConvexHull(p).vertices]; h = ConvexHull(p)\n"
        "    f = h.simplices.copy(); n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])\n"
        "    flip = ((p[f[:, 0]] - p.mean(0)) * n).sum(1) < 0; f[flip] = f[flip][:, [0, 2, 1]]\n"
        "    return LobeState(np.arange(len(p)), p.mean(0), p, f.astype(np.int32), True, np.zeros((0, 3)), 0, 0)\n"
        "d = depths([lobe(1.0), lobe(0.1)], 1, np.array([[0.0, 0, 0], [9.0, 0, 0]]))\n"
        "print(d[0] > 0.3, d[1] == 0, 'open3d' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["True", "True", "False"], out.stderr
