"""Leaf card geometry."""

from __future__ import annotations

import numpy as np

from arboretum_server.mesh.cards import WIDTH, card_mesh


def test_cards_are_quads_facing_their_normal(rng):
    k = 50
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a = np.cross(n, rng.normal(size=(k, 3)))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    c = rng.normal(size=(k, 3))
    s = rng.uniform(0.05, 0.1, k)
    m = card_mesh(c, n, a, s)
    assert m.positions.shape == (4 * k, 3) and m.faces.shape == (2 * k, 3)
    tri = m.positions[m.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.einsum("ij,ij->i", fn, np.repeat(n, 2, axis=0)) > 0).all()  # CCW seen from the normal
    area = np.linalg.norm(fn, axis=1).reshape(k, 2).sum(1) / 2
    assert np.allclose(area, s * s * WIDTH)
    assert np.allclose(m.positions.reshape(k, 4, 3).mean(1), c)
    stem = m.positions.reshape(k, 4, 3)[:, :2].mean(1)
    assert np.allclose(stem, c - a * s[:, None] / 2)
    assert m.uv.reshape(k, 4, 2)[:, :2, 1].min() == 1.0  # the stem at the image's bottom
