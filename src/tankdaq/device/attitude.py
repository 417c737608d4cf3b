"""Orientation forms the MTi sends besides Euler angles, from ZYX Euler angles (rad)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def quaternion(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> np.ndarray:
    """Unit quaternions (q0, q1, q2, q3) along the last axis."""
    cr, sr = np.cos(np.multiply(roll, 0.5)), np.sin(np.multiply(roll, 0.5))
    cp, sp = np.cos(np.multiply(pitch, 0.5)), np.sin(np.multiply(pitch, 0.5))
    cy, sy = np.cos(np.multiply(yaw, 0.5)), np.sin(np.multiply(yaw, 0.5))
    return np.stack(
        (
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ),
        axis=-1,
    )


def rotation_matrix(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> np.ndarray:
    """Body-to-earth rotation matrices, row-major flattened (9 values) along the last axis."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    return np.stack(
        (cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy,
         cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy,
         -sp, sr * cp, cr * cp),
        axis=-1,
    )  # fmt: skip
