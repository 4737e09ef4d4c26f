"""Transform maths for grip drags (the 'gizmo'): pure numpy, no state.

A grip drag gives ``delta = T_hand_now @ inv(T_hand_at_start)`` (world). Holding an example rigidly
in the hand means ``T_world_example' = delta @ T_world_example``. A lobe moves in its example's frame,
about its own centre: the world rotation is conjugated into the example frame and the world translation
is divided by the placement's scale.
"""

from __future__ import annotations

import numpy as np

from arboretum_client.assembly_view import orthonormalize


def drag_example(delta: np.ndarray, T_world_example: np.ndarray) -> np.ndarray:
    """(4, 4) new rigid T_world_example after a grip drag ``delta`` (4, 4)."""
    T = delta @ T_world_example
    T[:3, :3] = orthonormalize(T[:3, :3])
    T[3] = (0, 0, 0, 1)
    return T


def drag_lobe(delta: np.ndarray, T_world_example: np.ndarray, scale: float,
              T_example_lobe: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) new T_example_lobe: ``delta`` expressed in the example frame, composed after the old one.

    With ``p' = c + A (p - c) + t``, composing the drag (A_d, t_d) after (A_o, t_o) gives
    ``A = A_d A_o`` and ``t = A_d t_o + t_d``.
    """
    R = T_world_example[:3, :3]
    A_d = R.T @ orthonormalize(delta[:3, :3]) @ R
    t_d = R.T @ delta[:3, 3] / scale
    old = np.eye(4) if T_example_lobe is None else np.asarray(T_example_lobe, float)
    T = np.eye(4)
    T[:3, :3] = A_d @ old[:3, :3]
    T[:3, 3] = A_d @ old[:3, 3] + t_d
    return T


def scaled(T_example_lobe: np.ndarray, factor: float) -> np.ndarray:
    """The lobe transform with its linear part scaled by ``factor`` (about the lobe centre)."""
    T = np.array(T_example_lobe, float)
    T[:3, :3] *= factor
    return T


def place_at(position: np.ndarray, yaw_R: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) rigid transform putting an example's base at ``position`` (3,), upright."""
    T = np.eye(4)
    if yaw_R is not None:
        T[:3, :3] = orthonormalize(yaw_R)
    T[:3, 3] = position
    return T
