"""Parameters of the harmonic particle species model (Hoetzlein, Appendix A) and their checks.

A species is one ``SpeciesParams``: the general parameters and one ``LevelParams`` per hierarchy level
(level 0 is the trunk). Each level holds its branch spans (arc sections), wander terms, harmonic terms
and its ``LeafParams``. Angles are in degrees, spacings and lengths in growth steps (one internode per
step), sizes in metres. Fields marked "(ours)" are not in the paper's list; they name choices the paper
leaves implicit (branching angle, buds per node, first node, internode elongation).

Presets and random sampling of the space (``sample_species``) live in ``harmonic_presets.py``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from arboretum_library.codec import unflatten
from arboretum_library.errors import InputError, ValidationError

Quad = tuple[float, float, float, float]
IQuad = tuple[int, int, int, int]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class LeafParams:
    """Leaf parameters of one level (paper: LS_i, LP_i, LZ_i, theta_min_i, theta_max_i)."""

    spacing: int = 0
    """LS_i: a leaf site every ``spacing`` internodes along a branch of this level; 0 = no leaves."""
    probability: float = 1.0
    """LP_i: probability that a leaf site carries a leaf."""
    scale: float = 0.08
    """LZ_i: leaf length in metres (the card's X extent)."""
    angle_min: Vec3 = (-30.0, -30.0, -60.0)
    """theta_min_i: lower bound of the leaf orientation theta (intrinsic X, Y, Z Euler angles, degrees,
    about the card axes, starting from a blade along the bud direction with its face up)."""
    angle_max: Vec3 = (30.0, 30.0, 60.0)
    """theta_max_i: upper bound of theta; theta is drawn uniformly in [theta_min, theta_max]."""


@dataclass(frozen=True)
class LevelParams:
    """Parameters of hierarchy level i (0 = trunk): general per-level, spans, wander, harmonic, leaf."""

    taper: float = 0.02
    """TP_i: segment taper, the radial (secondary) growth of an internode per step, as a fraction of Z.
    An internode of age a has radius at least TP_i * Z * (a + 1); the pipe model thickens joints."""
    twist: float = 137.5
    """TW_i: segment twist in degrees per internode: the frame in which this level's lateral buds are
    placed rolls by TW_i per step (phyllotaxis; 137.5 = golden angle)."""
    node_spacing: int = 3
    """NS_i: a node (potential branching point) every NS_i internodes along a branch of this level."""
    node_probability: float = 1.0
    """NP_i: probability that a node site becomes a node."""
    length: int = 20
    """BL_i: branch length as terminal age: a level-i bud stops after BL_i internodes."""
    probability: float = 1.0
    """BP_i: branch probability: each candidate bud of a node becomes a level-i branch with BP_i."""
    span_spacing: IQuad = (0, 1000, 1000, 1000)
    """s_k,i: the age (internodes) at which span k starts; span k lasts until s_(k+1),i (equation 2)."""
    span_angle: Quad = (0.0, 0.0, 0.0, 0.0)
    """phi_k,i: the bend of span k in degrees per internode, positive upward (R_i, equation 2)."""
    wander_spacing: IQuad = (0, 0, 0, 0)
    """WS_k,i: wander term k turns the bud every WS_k,i internodes (equation 3); 0 = term off."""
    wander_amplitude: Quad = (0.0, 0.0, 0.0, 0.0)
    """WA_k,i: wander angle in degrees of term k, about a random axis across the bud (W_i)."""
    wander_noise: float = 0.0
    """WN_i: wander noise: each wander angle is scaled by 1 + WN_i * u, u uniform in [-1, 1]."""
    harmonic_frequency: Quad = (0.0, 0.0, 0.0, 0.0)
    """Hf_k,i: frequency of harmonic term k in radians per internode (H_i, equation 4)."""
    harmonic_amplitude: Quad = (0.0, 0.0, 0.0, 0.0)
    """Ha_k,i: amplitude of harmonic term k in degrees per internode; even k sway sideways (about
    the bud's local Y), odd k up and down (about its local X)."""
    angle: float = 45.0
    """(ours) Branching angle in degrees between the parent's direction and a new level-i bud; for
    level 0 the largest random lean of the trunk from vertical."""
    buds_per_node: int = 1
    """(ours) Candidate lateral buds per node of this level, spread evenly around it (a whorl if > 1)."""
    node_start: int = 0
    """(ours) Age (internodes) of the first node on a branch of this level (a clear bole or stalk)."""
    segment_scale: float = 1.0
    """(ours) Internode length of this level relative to Z (slower lateral growth: apical control)."""
    leaf: LeafParams = field(default_factory=LeafParams)
    """Leaf parameters of this level."""


@dataclass(frozen=True)
class SpeciesParams:
    """One species: general parameters (paper: S, A, L, Z) and one ``LevelParams`` per level."""

    max_age: int = 60
    """A: maximum age, the number of growth steps (= trunk internodes when BL_0 >= A)."""
    segment_size: float = 0.12
    """Z: initial internode length in metres."""
    levels: tuple[LevelParams, ...] = (LevelParams(),)
    """One entry per hierarchy level i = 0..L-1 (L = len(levels), the paper's L)."""
    elongation: float = 0.05
    """(ours) Primary elongation: every internode grows by ``elongation`` * Z per step of age ..."""
    elongation_max: float = 2.0
    """(ours) ... up to ``elongation_max`` times Z."""
    pipe_exponent: float = 2.5
    """(ours) Pipe-model exponent e: a joint's radius is at least (sum of children's r**e)**(1/e)."""
    variation: float = 0.08
    """(ours) Individual variation: the relative random change added to each parameter per tree."""
    max_particles: int = 200_000
    """(ours) Safety cap: no new lateral buds once this many particles exist."""

    def __post_init__(self) -> None:
        check_species(self)

    @property
    def level_count(self) -> int:
        """L, the number of hierarchy levels."""
        return len(self.levels)

    def to_dict(self) -> dict:
        """JSON-serialisable nested dict of every parameter (tuples become lists)."""
        return dataclasses.asdict(self)


def species_from_dict(data: Mapping[str, Any]) -> SpeciesParams:
    """``SpeciesParams`` from ``to_dict`` output (e.g. ``TreeTruth.parameters``); unknown keys ignored.

    A whole number written as an int (``82``, not ``82.0``) stays an int, also in a float field: the
    presets hold such ints, and ``individual`` rounds ints, so converting them to floats would grow a
    different tree from the same seed. The result therefore grows the same tree as the parameters that
    were saved.
    """
    try:
        params = unflatten(SpeciesParams, _as_lists(data), {})
    except ValidationError as exc:
        raise InputError(f"harmonic species parameters: {exc}") from None
    return _keep_ints(params, data)


def _as_lists(data: Any) -> Any:
    """``data`` with its tuples (as ``to_dict`` leaves them) turned into lists (as JSON gives them)."""
    if isinstance(data, Mapping):
        return {k: _as_lists(v) for k, v in data.items()}
    return [_as_lists(v) for v in data] if isinstance(data, tuple | list) else data


def _keep_ints(obj: Any, data: Any) -> Any:
    """``obj`` (a parameters dataclass, tuple or number) with the ints of ``data`` (its dict) restored."""
    if dataclasses.is_dataclass(obj) and isinstance(data, Mapping):
        changes = {f.name: _keep_ints(getattr(obj, f.name), data[f.name])
                   for f in dataclasses.fields(obj) if f.name in data}  # fmt: skip
        return dataclasses.replace(obj, **changes)
    if isinstance(obj, tuple) and isinstance(data, list | tuple) and len(obj) == len(data):
        return tuple(_keep_ints(o, d) for o, d in zip(obj, data))
    if type(data) is int and type(obj) is float and obj == data:
        return data
    return obj


def _fail(where: str, what: str) -> None:
    raise InputError(f"harmonic species parameter {where}: {what}")


def check_species(p: SpeciesParams) -> None:
    """Raise ``InputError`` naming the first parameter that is out of its valid range."""
    if not 1 <= p.max_age <= 2000:
        _fail("max_age (A)", f"must be in 1..2000, got {p.max_age}")
    if not p.segment_size > 0:
        _fail("segment_size (Z)", f"must be > 0, got {p.segment_size}")
    if not 1 <= len(p.levels) <= 8:
        _fail("levels (L)", f"need 1..8 levels, got {len(p.levels)}")
    if p.elongation < 0 or p.elongation_max < 1:
        _fail("elongation", "needs elongation >= 0 and elongation_max >= 1")
    if not 1 <= p.pipe_exponent <= 4:
        _fail("pipe_exponent", f"must be in 1..4, got {p.pipe_exponent}")
    if not 0 <= p.variation < 1:
        _fail("variation", f"must be in [0, 1), got {p.variation}")
    for i, lv in enumerate(p.levels):
        _check_level(f"levels[{i}]", lv)


def _check_level(w: str, lv: LevelParams) -> None:
    for name in ("node_probability", "probability"):
        if not 0 <= getattr(lv, name) <= 1:
            _fail(f"{w}.{name}", f"must be in [0, 1], got {getattr(lv, name)}")
    if not 0 <= lv.leaf.probability <= 1:
        _fail(f"{w}.leaf.probability", f"must be in [0, 1], got {lv.leaf.probability}")
    if lv.node_spacing < 1 or lv.length < 1 or lv.buds_per_node < 0 or lv.node_start < 0:
        _fail(w, "needs node_spacing >= 1, length >= 1, buds_per_node >= 0, node_start >= 0")
    if lv.taper <= 0 or lv.segment_scale <= 0 or lv.leaf.scale <= 0 or lv.leaf.spacing < 0:
        _fail(w, "needs taper > 0, segment_scale > 0, leaf.scale > 0 and leaf.spacing >= 0")
    if len(lv.span_spacing) != len(lv.span_angle) or list(lv.span_spacing) != sorted(lv.span_spacing):
        _fail(f"{w}.span_spacing", "needs one ascending start per span angle")
    if len(lv.wander_spacing) != len(lv.wander_amplitude) or min(lv.wander_spacing, default=0) < 0:
        _fail(f"{w}.wander_spacing", "needs one spacing >= 0 per wander amplitude")
    if len(lv.harmonic_frequency) != len(lv.harmonic_amplitude):
        _fail(f"{w}.harmonic_frequency", "needs one frequency per harmonic amplitude")
    if any(a > b for a, b in zip(lv.leaf.angle_min, lv.leaf.angle_max)):
        _fail(f"{w}.leaf.angle_min", "must not exceed angle_max")


def _vary(value, amount: float, rng: np.random.Generator):
    """``value`` (number or tuple) times 1 + amount * u, u uniform in [-1, 1]; ints stay ints."""
    if isinstance(value, tuple):
        return tuple(_vary(v, amount, rng) for v in value)
    out = value * (1.0 + amount * rng.uniform(-1.0, 1.0))
    if isinstance(value, int):
        return max(1, round(out)) if value >= 1 else value
    return float(out)


_LEVEL_VARIED = ("taper", "node_probability", "length", "probability", "span_angle",
                 "wander_amplitude", "harmonic_frequency", "harmonic_amplitude", "angle", "segment_scale")


def individual(p: SpeciesParams, rng: np.random.Generator) -> SpeciesParams:
    """One individual of species ``p``: a small random variation added to each parameter.

    Varies A, Z, and per level TP, NP, BL, BP, the span, wander and harmonic angles, the branching
    angle and the leaf scale by the relative amount ``p.variation``; probabilities stay in [0, 1].
    Spacings and counts (the species' structure) are kept.
    """
    v = p.variation
    levels = []
    for lv in p.levels:
        changes: dict[str, Any] = {name: _vary(getattr(lv, name), v, rng) for name in _LEVEL_VARIED}
        changes["node_probability"] = min(1.0, changes["node_probability"])
        changes["probability"] = min(1.0, changes["probability"])
        changes["leaf"] = dataclasses.replace(lv.leaf, scale=_vary(lv.leaf.scale, v, rng))
        levels.append(dataclasses.replace(lv, **changes))
    return dataclasses.replace(
        p, max_age=_vary(p.max_age, v, rng), segment_size=_vary(p.segment_size, v, rng),
        levels=tuple(levels),
    )
