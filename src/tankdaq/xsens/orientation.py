"""The MTi's three orientation outputs and the roll/pitch/yaw they mean (reference §2.4).

EulerAngles are Z-Y'-X'' (yaw, pitch, roll), right-handed, in the frame asked for (ENU here);
Quaternion (q0 scalar first) and RotationMatrix are the same sensor-to-earth rotation. A device
that refuses EulerAngles still gives the same roll and pitch through the other two: the
conversions here are exact inverses of each other, so every representation gives the angles the
device's own Euler output would have given.

RotationMatrix goes on the wire column by column: ``a..i`` with R = [[a d g], [b e h], [c f i]] (a real
MTi-G-710 capture that sends both, einride set 5, gives the same angles from its quaternion and from its
matrix read so; read row by row, yaw is off by 180 deg).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def quaternion(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> np.ndarray:
    """Unit quaternions (q0, q1, q2, q3) along the last axis, from ZYX Euler angles (rad)."""
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
    """Sensor-to-earth rotation matrices in wire order (column by column, 9 values) along the last axis."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    return np.stack(
        (cp * cy, cp * sy, -sp,
         sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, sr * cp,
         cr * sp * cy + sr * sy, cr * sp * sy - sr * cy, cr * cp),
        axis=-1,
    )  # fmt: skip


def euler_from_quaternion(q: ArrayLike) -> np.ndarray:
    """(roll, pitch, yaw) in rad along the last axis of quaternions (q0, q1, q2, q3), normalised first."""
    given = np.asarray(q, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):  # an all-zero quaternion is NaN angles
        unit = given / np.linalg.norm(given, axis=-1, keepdims=True)
    q0, q1, q2, q3 = np.moveaxis(unit, -1, 0)
    roll = np.arctan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
    pitch = np.arcsin(np.clip(2 * (q0 * q2 - q3 * q1), -1.0, 1.0))
    yaw = np.arctan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
    return np.stack((roll, pitch, yaw), axis=-1)


def euler_from_matrix(m: ArrayLike) -> np.ndarray:
    """(roll, pitch, yaw) in rad along the last axis of rotation matrices in wire order (9 values)."""
    matrix = np.asarray(m, dtype=float)
    r11, r21, r31, r32, r33 = (matrix[..., k] for k in (0, 1, 2, 5, 8))  # column-major: R[i, j] is m[3j + i]
    roll = np.arctan2(r32, r33)
    pitch = np.arcsin(np.clip(-r31, -1.0, 1.0))
    yaw = np.arctan2(r21, r11)
    return np.stack((roll, pitch, yaw), axis=-1)
