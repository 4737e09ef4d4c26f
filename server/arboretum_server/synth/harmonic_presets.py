"""Species presets of the harmonic model, and random sampling of its parameter space ("discovery").

Presets are tuned by eye and by silhouette statistics (``harmonic.silhouette_stats``) to read as the
species in outline; they are not fitted to measurements. ``sample_species`` draws a new species from
documented plausible bounds (``SAMPLE_BOUNDS``), as in the paper's Figure 6.
"""

from __future__ import annotations

import numpy as np

from .species import LeafParams as Leaf
from .species import LevelParams as Lv
from .species import SpeciesParams

NEVER = 1000
"""A span start beyond any branch's age (the span never begins)."""

_NEEDLES = Leaf(spacing=1, probability=1.0, scale=0.10, angle_min=(-40, -40, -90), angle_max=(40, 40, 90))
_BROAD = Leaf(spacing=1, probability=0.9, scale=0.10, angle_min=(-35, -25, -50), angle_max=(35, 25, 50))


def _pine() -> SpeciesParams:
    return SpeciesParams(max_age=70, segment_size=0.15, elongation=0.04, elongation_max=1.5, levels=(
        Lv(taper=0.025, twist=36, node_spacing=4, node_probability=0.95, length=70, angle=2,
           buds_per_node=5, node_start=6, wander_spacing=(6, 0, 0, 0), wander_amplitude=(1.5, 0, 0, 0)),
        Lv(taper=0.006, twist=90, node_spacing=3, length=60, probability=0.9, angle=82, segment_scale=0.3,
           span_spacing=(0, 8, 16, NEVER), span_angle=(-1.5, 0.0, 1.5, 0.0), buds_per_node=2,
           wander_spacing=(4, 0, 0, 0), wander_amplitude=(3, 0, 0, 0), wander_noise=0.5),
        Lv(taper=0.004, length=6, angle=55, probability=0.9, segment_scale=0.4, leaf=_NEEDLES),
    ))


def _oak() -> SpeciesParams:
    return SpeciesParams(max_age=60, segment_size=0.14, levels=(
        Lv(taper=0.03, node_spacing=2, length=24, angle=4, node_start=11,
           wander_spacing=(3, 7, 0, 0), wander_amplitude=(4, 6, 0, 0), wander_noise=0.5),
        Lv(taper=0.012, node_spacing=3, length=34, angle=60, span_spacing=(0, 10, 22, NEVER),
           span_angle=(-0.6, 0.5, 1.2, 0), wander_spacing=(3, 5, 0, 0), wander_amplitude=(6, 8, 0, 0),
           wander_noise=0.6, harmonic_frequency=(0.45, 0.3, 0, 0), harmonic_amplitude=(3, 2, 0, 0)),
        Lv(taper=0.007, node_spacing=2, length=12, angle=50, span_angle=(0.5, 0, 0, 0),
           wander_spacing=(3, 0, 0, 0), wander_amplitude=(8, 0, 0, 0)),
        Lv(taper=0.005, length=4, angle=45, leaf=_BROAD),
    ))


def _apple() -> SpeciesParams:
    return SpeciesParams(max_age=40, segment_size=0.1, levels=(
        Lv(taper=0.03, node_spacing=2, length=14, angle=5, node_start=7,
           wander_spacing=(3, 0, 0, 0), wander_amplitude=(5, 0, 0, 0)),
        Lv(taper=0.01, node_spacing=1, length=26, angle=55, span_spacing=(0, 8, 16, NEVER),
           span_angle=(0.6, -0.6, -1.8, 0), wander_spacing=(3, 0, 0, 0), wander_amplitude=(8, 0, 0, 0),
           wander_noise=0.5),
        Lv(taper=0.007, node_spacing=2, length=8, angle=50, span_angle=(-0.5, 0, 0, 0),
           wander_spacing=(2, 0, 0, 0), wander_amplitude=(8, 0, 0, 0), segment_scale=0.8),
        Lv(taper=0.005, length=3, angle=45, segment_scale=0.6, leaf=_BROAD),
    ))


def _cherry() -> SpeciesParams:
    return SpeciesParams(max_age=45, segment_size=0.11, levels=(
        Lv(taper=0.03, node_spacing=2, length=16, angle=4, node_start=8,
           wander_spacing=(4, 0, 0, 0), wander_amplitude=(3, 0, 0, 0)),
        Lv(taper=0.01, node_spacing=1, length=28, angle=40, span_spacing=(0, 12, 20, NEVER),
           span_angle=(0.4, -0.8, -1.6, 0), harmonic_frequency=(0.3, 0, 0, 0),
           harmonic_amplitude=(2, 0, 0, 0)),
        Lv(taper=0.007, node_spacing=2, length=9, angle=45, span_angle=(-0.8, 0, 0, 0),
           segment_scale=0.8),
        Lv(taper=0.005, length=3, angle=45, segment_scale=0.6, leaf=_BROAD),
    ))


def _eucalyptus() -> SpeciesParams:
    return SpeciesParams(max_age=80, segment_size=0.18, levels=(
        Lv(taper=0.022, node_spacing=3, node_probability=0.8, length=80, angle=5, node_start=36,
           wander_spacing=(4, 9, 0, 0), wander_amplitude=(1.5, 2.5, 0, 0), wander_noise=0.5),
        Lv(taper=0.008, node_spacing=3, node_probability=0.85, length=28, angle=35,
           span_spacing=(0, 12, NEVER, NEVER), span_angle=(0.5, -0.7, 0, 0),
           wander_spacing=(3, 5, 0, 0), wander_amplitude=(10, 8, 0, 0), wander_noise=0.7),
        Lv(taper=0.005, node_spacing=2, length=9, angle=45, probability=0.8, segment_scale=0.8,
           span_angle=(-1.5, 0, 0, 0), wander_spacing=(2, 0, 0, 0), wander_amplitude=(8, 0, 0, 0)),
        Lv(taper=0.004, length=3, angle=40, segment_scale=0.6,
           leaf=Leaf(spacing=1, scale=0.14, angle_min=(-20, 40, -20), angle_max=(20, 80, 20))),
    ))


def _ginkgo() -> SpeciesParams:
    return SpeciesParams(max_age=60, segment_size=0.14, levels=(
        Lv(taper=0.025, node_spacing=2, node_probability=0.75, length=60, angle=4, node_start=10,
           wander_spacing=(4, 0, 0, 0), wander_amplitude=(4, 0, 0, 0), wander_noise=0.5),
        Lv(taper=0.008, node_spacing=1, node_probability=0.85, length=22, angle=38,
           span_angle=(0.5, 0, 0, 0), wander_spacing=(3, 6, 0, 0), wander_amplitude=(9, 10, 0, 0),
           wander_noise=0.8, segment_scale=0.8),
        Lv(taper=0.004, length=3, angle=60, segment_scale=0.3,
           leaf=Leaf(spacing=1, scale=0.07, angle_min=(-50, -50, -90), angle_max=(50, 50, 90))),
    ))


def _walnut() -> SpeciesParams:
    return SpeciesParams(max_age=55, segment_size=0.13, levels=(
        Lv(taper=0.03, node_spacing=2, length=24, angle=4, node_start=9,
           wander_spacing=(4, 0, 0, 0), wander_amplitude=(4, 0, 0, 0)),
        Lv(taper=0.01, node_spacing=2, length=32, angle=58, span_spacing=(0, 10, 20, NEVER),
           span_angle=(0.4, -0.4, -1.2, 0), wander_spacing=(4, 0, 0, 0), wander_amplitude=(6, 0, 0, 0),
           harmonic_frequency=(0.3, 0, 0, 0), harmonic_amplitude=(2, 0, 0, 0)),
        Lv(taper=0.007, node_spacing=2, length=10, angle=45, span_angle=(0.3, 0, 0, 0),
           segment_scale=0.8),
        Lv(taper=0.005, length=3, angle=45, segment_scale=0.6, leaf=_BROAD),
    ))


def _birch() -> SpeciesParams:
    return SpeciesParams(max_age=70, segment_size=0.13, levels=(
        Lv(taper=0.016, node_spacing=2, length=70, angle=3, node_start=14,
           wander_spacing=(5, 0, 0, 0), wander_amplitude=(2, 0, 0, 0)),
        Lv(taper=0.006, node_spacing=2, length=24, angle=40, span_spacing=(0, 7, 14, NEVER),
           span_angle=(0.5, -1.5, -3.5, 0), harmonic_frequency=(0.5, 0, 0, 0),
           harmonic_amplitude=(2.5, 0, 0, 0), segment_scale=0.8),
        Lv(taper=0.004, node_spacing=2, length=12, angle=30, span_angle=(-7.0, 0, 0, 0),
           segment_scale=0.6, leaf=Leaf(spacing=1, probability=0.8, scale=0.06)),
        Lv(taper=0.003, length=2, angle=40, segment_scale=0.5, leaf=Leaf(spacing=1, scale=0.06)),
    ))


SPECIES: dict[str, SpeciesParams] = {
    "apple": _apple(),
    "birch": _birch(),
    "cherry": _cherry(),
    "eucalyptus": _eucalyptus(),
    "ginkgo": _ginkgo(),
    "oak": _oak(),
    "pine": _pine(),
    "walnut": _walnut(),
}
"""The presets by lower-case name: VRTree's library species plus birch and oak."""


SAMPLE_BOUNDS: dict[str, tuple[float, float]] = {
    "max_age": (30, 80),
    "segment_size": (0.08, 0.2),
    "levels": (3, 4),
    "trunk_length_fraction": (0.25, 1.0),
    "node_start_fraction": (0.05, 0.5),
    "taper_trunk": (0.015, 0.035),
    "taper_decay": (0.3, 0.7),
    "node_spacing": (1, 4),
    "node_probability": (0.6, 1.0),
    "buds_per_node": (1, 4),
    "twist": (30.0, 180.0),
    "branch_length": (6, 36),
    "branch_length_decay": (0.2, 0.5),
    "probability": (0.6, 1.0),
    "angle": (25.0, 85.0),
    "span_angle": (-3.0, 2.0),
    "wander_amplitude": (0.0, 10.0),
    "harmonic_amplitude": (0.0, 3.0),
    "harmonic_frequency": (0.1, 0.8),
    "segment_scale": (0.3, 1.0),
    "leaf_scale": (0.04, 0.15),
}
"""Plausible bounds of ``sample_species`` (uniform; integers inclusive). The trunk length is a
fraction of A, its first node a fraction of the trunk length; the
``*_decay`` factors shrink taper and branch length from one level to the next."""


def sample_species(rng: np.random.Generator) -> SpeciesParams:
    """A random species drawn within ``SAMPLE_BOUNDS`` (the paper's "discovery" of species, Fig. 6).

    The trunk (level 0) has a lean of at most 5 degrees and no span arcs; each further level draws
    its branching angle, four span arcs at increasing ages, two wander and two harmonic terms; only
    the last level bears leaves. Every draw is a valid ``SpeciesParams``.
    """
    B = SAMPLE_BOUNDS

    def u(key: str) -> float:
        return float(rng.uniform(*B[key]))

    def i(key: str) -> int:
        lo, hi = B[key]
        return int(rng.integers(int(lo), int(hi) + 1))

    age = i("max_age")
    n_levels = i("levels")
    length, taper = max(4, round(age * u("trunk_length_fraction"))), u("taper_trunk")
    levels = [Lv(taper=taper, node_spacing=i("node_spacing"), length=length, angle=5.0,
                 node_start=round(length * u("node_start_fraction")), twist=u("twist"),
                 wander_spacing=(i("node_spacing") + 2, 0, 0, 0), wander_amplitude=(u("wander_amplitude") / 3, 0, 0, 0))]
    length = u("branch_length")
    for lvl in range(1, n_levels):
        taper *= u("taper_decay")
        last = lvl == n_levels - 1
        starts = np.sort(rng.integers(1, max(2, round(length)), 3))
        levels.append(Lv(
            taper=taper, twist=u("twist"), node_spacing=i("node_spacing"),
            node_probability=u("node_probability"), length=max(1, round(length)),
            probability=u("probability"), angle=u("angle"), buds_per_node=i("buds_per_node"),
            span_spacing=(0, int(starts[0]), int(starts[1]), int(starts[2])),
            span_angle=(u("span_angle"), u("span_angle"), u("span_angle"), u("span_angle")),
            wander_spacing=(int(rng.integers(2, 6)), int(rng.integers(4, 9)), 0, 0),
            wander_amplitude=(u("wander_amplitude"), u("wander_amplitude"), 0.0, 0.0), wander_noise=0.5,
            harmonic_frequency=(u("harmonic_frequency"), u("harmonic_frequency"), 0.0, 0.0),
            harmonic_amplitude=(u("harmonic_amplitude"), u("harmonic_amplitude"), 0.0, 0.0),
            segment_scale=u("segment_scale"),
            leaf=Leaf(spacing=1, scale=u("leaf_scale")) if last else Leaf(spacing=0),
        ))
        length = max(2.0, length * u("branch_length_decay") * 1.5)
    return SpeciesParams(max_age=age, segment_size=u("segment_size"), levels=tuple(levels),
                         max_particles=60_000)
