"""Limits of a growth, checked before it starts (``arboretum grow``, and ``grow``/``export.mesh``
requests to the server): options far beyond any real use, and an estimate of the tree's size, so a
mistake is one error instead of gigabytes (docs/growth.md, "Limits of the options")."""

from __future__ import annotations

from arboretum_library.errors import InputError

MAX_DENSITY = 20.0
"""Largest --density: ten times the densest setting we use (2.1 in the bench). Memory and time grow
about linearly with it (docs/growth.md: about 0.7 GB and 5 s at 20 on a 40-lobe scan)."""
MAX_LEAF_DENSITY = 20.0
"""Largest --leaf-density (leaf cards per tip node, default 1): about 0.4 GB at 20 on a 40-lobe scan."""
MAX_STEP_REFINE = 4.0
"""Smallest --step: the default step (1/6 of the median lobe radius) divided by this (64 times as many
attraction points; at /5 a 40-lobe scan grew 608,181 twig nodes in 67 s and 2.8 GB)."""
MAX_ELEMENTS = 1_500_000
"""Largest estimated twig nodes + leaf cards (``estimate_size``): about 120 times the default growth
of a 40-lobe scan, 3.3-6 GB of memory at the measured 2.2-4 KB each (docs/growth.md, "Limits of the
options")."""
BYTES_PER_ELEMENT = 3000
"""Peak memory per twig node or leaf card, growth through GLB (measured 2.2-4 KB), for the message."""
LEAF_SHARE = 0.7
"""Share of twig nodes that bear leaves, an upper estimate (measured 0.50-0.67)."""


def check_step(step: float | None, lobes) -> str | None:
    """``InputError`` when ``--step`` is finer than the default step (1/6 of the median lobe radius)
    over ``MAX_STEP_REFINE``, or larger than every lobe; a note (str) when it exceeds the median lobe
    radius (most lobes then grow nothing); None otherwise."""
    from .attraction import default_step, equivalent_radius

    if step is None or not lobes:
        return None
    d0 = default_step(lobes)
    radii = [equivalent_radius(lb) for lb in lobes]
    if step < d0 / MAX_STEP_REFINE:
        raise InputError(f"--step {step:g} m is too fine for these lobes: the smallest is "
                         f"{d0 / MAX_STEP_REFINE:.3g} m (the default {d0:.3g} m / {MAX_STEP_REFINE:g})")
    if step > max(radii):
        raise InputError(f"--step {step:g} m is larger than every lobe (the largest has radius "
                         f"{max(radii):.3g} m): no twig would grow; the default is {d0:.3g} m")
    if step > 6 * d0:
        return (f"note: --step {step:g} m is larger than half the lobes (median radius {6 * d0:.3g} m); "
                "few twigs will grow")
    return None


def estimate_size(lobes, opts) -> tuple[int, int]:
    """(twig nodes, leaf cards) a growth with ``opts`` will make at most, about: one twig node per
    attraction point (``attraction.attraction_points``' count; measured 0.5-1.1), ``LEAF_SHARE`` of
    them bearing ``leaf_density`` cards."""
    import numpy as np

    from .attraction import default_step
    from .hulls import mesh_volume

    if not lobes:
        return 0, 0
    step = opts.step if opts.step is not None else default_step(lobes)
    hull = np.array([len(lb.hull_vertices) for lb in lobes], np.float64)
    volume = np.array([mesh_volume(lb.hull_vertices, lb.hull_faces) for lb in lobes])
    mult = np.array([opts.lobe_multiplier(i) for i in range(len(lobes))])
    cap = np.maximum(opts.max_points_per_lobe - hull, 0)
    interior = np.minimum(np.round(opts.attraction_density * mult * volume / step**3), cap)
    nodes = int((interior + hull)[mult > 0].sum())
    return nodes, int(LEAF_SHARE * opts.leaf_density * nodes)


def check_size(lobes, opts) -> None:
    """``InputError`` naming the estimate when the tree would exceed ``MAX_ELEMENTS``."""
    nodes, leaves = estimate_size(lobes, opts)
    if nodes + leaves > MAX_ELEMENTS:
        gb = (nodes + leaves) * BYTES_PER_ELEMENT / 1e9
        raise InputError(f"--density {opts.density:g}, --leaf-density {opts.leaf_density:g} and --step "
                         f"{opts.step if opts.step is not None else 'default'} would grow about {nodes:,} twig "
                         f"nodes and {leaves:,} leaf cards (about {gb:.0f} GB of memory), over the limit of "
                         f"{MAX_ELEMENTS:,} together; lower --density or --leaf-density, or raise --step")
