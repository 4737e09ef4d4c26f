"""Named guiding-vector presets (``arboretum synth --model guiding --species NAME``).

All share a 12 x 12 x 12 m graph box of 60,000 nodes, a straight trunk in the first iteration (one
endpoint, alpha = 0) and a crown half-ellipsoid for the second iteration's endpoints (sections 3.2.2
and 3.1.4); they differ in the second iteration's rotation rule and the endpoint rules of the later
iterations:

* ``default``  Fig. 6(d): alpha_1 = 15, alpha_2 = -5, h_0 = 5, then straight twigs (30, 0, 1);
* ``hanging``  a weeping tree (Fig. 13): alpha = 10 droops the branches, later endpoints must lie
  below their sources;
* ``upward``   Fig. 6(b) (alpha_1 = 60, h_0 = 1, alpha_2 = 0) and every later endpoint above its source;
* ``helical``  a helical field (Fig. 8a) for the branches;
* ``elm``      Eq. 2 with theta = 25 (Fig. 7);
* ``ash``      alpha_1 = R in [30, 120] (Fig. 6c).

The crowns are NOT kept clear of the box: every preset has branch tips within 0.1 m of a side wall
(0.4-2.9 % of its tips; docs/synthetic.md, "Limits: the graph box"). The box stays as it is because
these trees are the ground truth of the decomposition evaluation; a larger box grows other trees.
"""

from __future__ import annotations

from dataclasses import replace

from .endpoints import Volume
from .fields import Rotation
from .guiding import GuidingOptions, Iteration

TRUNK = Iteration(Rotation("piecewise", 0.0, 0.0, 0), endpoints=1,
                  volume=Volume("ellipsoid", (0.0, 0.0, 4.5), (0.5, 0.5, 0.5)))  # fmt: skip
CROWN = Volume("half_ellipsoid", (0.0, 0.0, 3.5), (3.5, 3.5, 5.5))
TWIGS = Rotation("piecewise", 30.0, 0.0, 1)


def _tree(branches: Rotation, rule: str = "none", crown: Volume = CROWN) -> GuidingOptions:
    return GuidingOptions(
        iterations=(
            TRUNK,
            Iteration(branches, endpoints=40, volume=crown),
            Iteration(TWIGS, endpoints=160, k=5, t=0.6, rule=rule),
            Iteration(TWIGS, endpoints=500, k=3, t=0.6, rule=rule),
            Iteration(TWIGS, endpoints=1200, k=2, t=0.6, rule=rule),
        )
    )


PRESETS: dict[str, GuidingOptions] = {
    "default": _tree(Rotation("piecewise", 15.0, -5.0, 5)),
    "hanging": _tree(Rotation("piecewise", 10.0, 10.0, 0), rule="hanging"),
    "upward": _tree(Rotation("piecewise", 60.0, 0.0, 1), rule="upward"),
    "helical": _tree(Rotation("helical", pitch=30.0)),
    "elm": _tree(Rotation("global", theta=25.0)),
    "ash": _tree(
        Rotation("random", alpha2=0.0, h0=1), crown=Volume("box", (0.0, 0.0, 6.5), (3.0, 3.0, 2.5))
    ),
}


def preset(name: str, **overrides) -> GuidingOptions:
    """The preset ``name`` with fields replaced by ``overrides`` (e.g. nodes=20000)."""
    return replace(PRESETS[name], **overrides)
