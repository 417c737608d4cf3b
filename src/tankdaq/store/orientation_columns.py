"""Roll and pitch from a file's orientation columns, whichever representation the file holds.

MT Manager (and the loggers that copy its names) writes the device's orientation as Euler angles
(``Roll``/``Pitch``/``Yaw`` or ``Euler_X``/``Euler_Y``/``Euler_Z``, degrees), a unit quaternion
(``Quat_q0``..``Quat_q3``, scalar first) or a rotation matrix (``Mat[i][j]``, row i, column j of the
sensor-to-earth matrix). Taken as an angle, a quaternion component is a sine of half the angle and a matrix
entry a product of cosines: a 10 deg decay read from ``Quat_q1`` is "1.8 deg" with every amplitude term
wrong and no error. So each column is recognised by its name (any case, with or without a unit suffix),
a quaternion or matrix component given as the angle is refused, and without an angle column the decay
axis comes from the best representation there is: Euler angles as written, else the quaternion, else the
matrix, converted exactly as the device converts them (Z-Y'-X'', ``xsens.orientation``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..xsens.orientation import euler_from_matrix, euler_from_quaternion

#: A unit a column name may carry after the quantity: ``Roll_deg``, ``Roll (deg)``, ``Roll [rad]``.
_UNIT = re.compile(r"[\s_]*[\(\[]?\s*(deg|degrees?|rad|radians?|°)\s*[\)\]]?$", re.IGNORECASE)
_EULER = {"roll": 0, "pitch": 1, "yaw": 2, "euler_x": 0, "euler_y": 1, "euler_z": 2, "eulerx": 0, "eulery": 1}
_EULER |= {"eulerz": 2, "euler_roll": 0, "euler_pitch": 1, "euler_yaw": 2}
_QUATERNION = re.compile(r"^quat(?:ernion)?[_ .]?(?:q_?([0-3])|([0-3])|([wxyz]))$")
_MATRIX = re.compile(r"^(?:mat|matrix|rotmat|rotationmatrix)[_ .]?\[?([1-3])\]?[_ ,.]?\[?([1-3])\]?$")
AXES = ("roll", "pitch")


@dataclass(frozen=True)
class Orientation:
    """The decay axis taken from a file's orientation columns: the angle (rad) or the Euler column to read
    as the file gives it, and the one line that says which columns and how."""

    column: str | None  # an Euler column, read with its unit as any angle column
    angle_rad: np.ndarray | None  # the angle computed from a quaternion or matrix
    line: str


def _plain(name: str) -> str:
    return _UNIT.sub("", name.strip()).lower().replace(" ", "_")


def euler_index(name: str) -> int | None:
    """0, 1, 2 for a roll, pitch, yaw column name; None for any other."""
    return _EULER.get(_plain(name))


def quaternion_index(name: str) -> int | None:
    """0..3 for a quaternion component's name (``Quat_q0``, ``Quat2``, ``Quat_w``: a bare ``q1`` may be a
    pitch rate, so the prefix is asked for); None for any other."""
    found = _QUATERNION.match(_plain(name))
    if found is None:
        return None
    number = found.group(1) or found.group(2)
    return int(number) if number is not None else "wxyz".index(found.group(3))


def matrix_index(name: str) -> int | None:
    """The wire index (column by column, ``xsens.orientation``) of a matrix entry's name (``Mat[2][3]``,
    ``Mat_23``: row 2, column 3); None for any other."""
    found = _MATRIX.match(_plain(name))
    if found is None:
        return None
    row, column = int(found.group(1)) - 1, int(found.group(2)) - 1
    return 3 * column + row


def refuse_component(path: object, name: str, axis: str) -> None:
    """A quaternion component or matrix entry given as the angle column: one line naming the option."""
    if quaternion_index(name) is not None:
        what, whole = "a quaternion component", "quaternion"
    elif matrix_index(name) is not None:
        what, whole = "a rotation-matrix entry", "rotation matrix"
    else:
        return
    raise InputError(
        f"{path}: column {name!r} is {what}, not an angle: leave out --angle-col and the {axis} angle is "
        f"taken from the whole {whole} (choose the axis with --axis roll or --axis pitch)"
    )


def find_orientation(columns: dict[str, np.ndarray], axis: str) -> Orientation | None:
    """The ``axis`` angle from the orientation columns there are (Euler, else a whole quaternion, else a
    whole matrix); None when the file has none of them."""
    index = AXES.index(axis)
    euler = {euler_index(name): name for name in columns if euler_index(name) is not None}
    if index in euler:
        name = euler[index]
        return Orientation(name, None, f"{axis} angle from column {name!r} (the device's Euler angles)")
    quaternion = {quaternion_index(name): name for name in columns if quaternion_index(name) is not None}
    if len(quaternion) == 4:
        names = [quaternion[k] for k in range(4)]
        angles = euler_from_quaternion(np.stack([columns[n] for n in names], axis=-1))
        return Orientation(None, angles[:, index], _line(axis, "the quaternion", names))
    matrix = {matrix_index(name): name for name in columns if matrix_index(name) is not None}
    if len(matrix) == 9:
        names = [matrix[k] for k in range(9)]
        angles = euler_from_matrix(np.stack([columns[n] for n in names], axis=-1))
        return Orientation(None, angles[:, index], _line(axis, "the rotation matrix", names))
    return None


def _line(axis: str, what: str, names: list[str]) -> str:
    return (
        f"{axis} angle from {what} {names[0]}..{names[-1]} (Z-Y'-X'' Euler angles, as the device's own "
        "output gives them)"
    )
