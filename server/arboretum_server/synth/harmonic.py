"""The harmonic particle species model (Hoetzlein, "A Procedural Model for Diverse Tree Species").

Apical buds are particles that move one internode per growth step. Each step every active bud emits a
particle (a skeleton node), then turns by equation 1, ``B(t+1) = B(t) R_i(t) W_i(t) H_i(t)``: the span
arc R (eq. 2), the wander term W (eq. 3) and the harmonic term H (eq. 4), all as quaternions in the
bud's own frame, whose local +X is kept horizontal at birth so that a positive span angle bends up.
Every NS_i internodes a bud may form a node (NP_i) whose candidate buds (BP_(i+1)) start branches of
the next level; a bud stops at its terminal age BL_i. All buds of a step advance together as numpy
arrays. Internodes elongate and thicken with age (all internodes grow every step), and the pipe model
keeps every joint at least as thick as its children. See ``species.py`` for the parameters.

Public entry point: ``grow_species(species, seed, steps=None) -> TreeTruth``.
"""

from __future__ import annotations

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.truth import TreeTruth

from . import quat
from .harmonic_growth import Particles, grow_particles
from .harmonic_presets import SPECIES
from .species import SpeciesParams, individual

__all__ = ["SPECIES", "grow_species", "silhouette_stats", "resolve_species"]

# card X -> bud +Z (blade along the shoot), card Y -> bud -X, card Z (face) -> bud -Y (up-ish)
_LEAF_BASE = quat.from_matrix(np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]))


def resolve_species(species: str | SpeciesParams) -> tuple[str, SpeciesParams]:
    """(name, parameters) of a preset name (case-insensitive) or of given parameters ('custom')."""
    if isinstance(species, SpeciesParams):
        return "custom", species
    name = str(species).strip().lower()
    if name not in SPECIES:
        raise InputError(f"unknown harmonic species {species!r}; choose one of {', '.join(sorted(SPECIES))}")
    return name, SPECIES[name]


def grow_species(species: str | SpeciesParams, seed: int, *, steps: int | None = None) -> TreeTruth:
    """Grow one individual of ``species`` (preset name or parameters) from ``seed``.

    Args:
        species: a key of ``SPECIES`` (e.g. 'pine') or a ``SpeciesParams``.
        seed: seed of the numpy Generator; the same seed gives the identical tree.
        steps: growth steps to run (default: the individual's maximum age A); fewer give a younger tree.

    Returns:
        The tree as a ``TreeTruth`` (model 'harmonic'): one node per particle, branch order = level.
    """
    name, base = resolve_species(species)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be a whole number >= 0, got {seed!r}")
    if steps is not None and (isinstance(steps, bool) or int(steps) != steps or steps < 1):
        raise InputError(f"steps must be a whole number >= 1, got {steps!r}")
    seed = int(seed)
    rng = np.random.default_rng(seed)
    params = individual(base, rng)
    n_steps = params.max_age if steps is None else int(steps)
    parts = grow_particles(params, rng, n_steps)
    return _to_truth(parts, params, name, base, seed, n_steps)


def _to_truth(p: Particles, params: SpeciesParams, name: str, base: SpeciesParams,
              seed: int, steps: int) -> TreeTruth:
    positions = p.positions()
    lq = quat.normalize(quat.mul(p.q[p.leaf_node], quat.mul(_LEAF_BASE, quat.from_euler_xyz(p.leaf_theta))))
    blade = quat.rotate(lq, quat.EX)
    leaf_pos = positions[p.leaf_node] + 0.5 * p.leaf_size[:, None] * blade
    return TreeTruth(
        positions=positions,
        radii=p.radii(),
        parent=p.parent,
        branch_id=p.branch,
        branch_order=p.level,
        leaf_positions=leaf_pos,
        leaf_wxyz=lq,
        leaf_sizes=p.leaf_size,
        leaf_node=p.leaf_node,
        model="harmonic",
        species=name,
        seed=seed,
        parameters={**base.to_dict(), "steps": steps},
    )


def silhouette_stats(truth: TreeTruth) -> dict[str, float]:
    """Simple silhouette statistics of a tree (skeleton nodes and leaf centres).

    Returns:
        height (m, top minus root), width (m, mean of the X and Y extents), height_width (ratio),
        crown_base (fraction of the height below the lowest 2 % of branch (order >= 1) nodes),
        top_width (width of the top quarter over the width: ~0 for a cone, ~1 for a dome).
    """
    pts = np.concatenate([truth.positions, truth.leaf_positions])
    z0 = truth.positions[0, 2]
    height = float(pts[:, 2].max() - z0)
    lo, hi = np.percentile(pts[:, :2], [1, 99], axis=0)
    width = float((hi - lo).mean())
    side = truth.positions[truth.branch_order >= 1]
    crown_base = float((np.percentile(side[:, 2], 2) - z0) / height) if len(side) else 1.0
    top = pts[pts[:, 2] > z0 + 0.75 * height]
    tlo, thi = np.percentile(top[:, :2], [1, 99], axis=0)
    return {
        "height": height,
        "width": width,
        "height_width": height / max(width, 1e-9),
        "crown_base": crown_base,
        "top_width": float((thi - tlo).mean() / max(width, 1e-9)),
    }
