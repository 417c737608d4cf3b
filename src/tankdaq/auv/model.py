"""The diving-plane equations of motion and the zigzag-like manoeuvre (seed 003 eq. 1, completed).

    (m - r3 X'udot) du/dt = -m w q + r3 X'wq w q + r2 (X'u|u| u|u| + X'dsds u^2 ds^2) + X_T
                            - (W - B) sin(theta)
    (m - r3 Z'wdot) dw/dt - r4 Z'qdot dq/dt = m u q + r3 Z'uq u q
                     + r2 (Z'uu u^2 + Z'uw u w + Z'w|w| w|w| + Z'ds u^2 ds) + (W - B) cos(theta)
    (Iy - r5 M'qdot) dq/dt - r4 M'wdot dw/dt = r5 M'q|q| q|q| + r4 M'uq u q
                     + r3 (M'uu u^2 + M'uw u w + M'w|w| w|w| + M'ds u^2 ds) - BG B sin(theta)
    dx/dt = u cos(theta) + w sin(theta),  dz/dt = -u sin(theta) + w cos(theta),  dtheta/dt = q

with rn = rho/2 L^n, the origin at the centre of gravity (as in the seed), z down and theta nose-up.
The stern plane follows its command through a first-order servo. Integration is fixed-step RK4 compiled
with numba: the sensitivity analysis re-simulates the manoeuvre dozens of times, and plane switches
are located inside a step (cubic Hermite on theta) so outputs vary smoothly with the derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..errors import InputError
from ..ident.user_cache import use_user_cache_for_numba
from .vehicle import Vehicle

use_user_cache_for_numba()  # numba's cache in the user cache folder, never beside an installed source

#: Recorded state columns, in order (SI units, angles in rad).
STATE_COLUMNS: tuple[str, ...] = ("u", "w", "q", "theta", "z", "x", "delta_s")
STATE_UNITS: dict[str, str] = {
    "t": "s",
    "u": "m/s",
    "w": "m/s",
    "q": "rad/s",
    "theta": "rad",
    "z": "m",
    "x": "m",
    "delta_s": "rad",
}
_PARAM_DERIVATIVES: tuple[str, ...] = (
    "X_wq",
    "X_u|u|",
    "X_dsds",
    "Z_uq",
    "Z_uu",
    "Z_uw",
    "Z_w|w|",
    "Z_ds",
    "M_q|q|",
    "M_uq",
    "M_uu",
    "M_uw",
    "M_w|w|",
    "M_ds",
)
#: Longest manoeuvre simulated before giving up on reaching the pitch threshold.
MAX_DURATION_S = 900.0


@dataclass
class StateRecord:
    """A diving-plane time history: sample times and the STATE_COLUMNS, plus what it is."""

    t: np.ndarray
    states: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    switch_times: np.ndarray = field(default_factory=lambda: np.empty(0))

    def __getitem__(self, column: str) -> np.ndarray:
        return self.states[column]

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t)))


def pack_parameters(vehicle: Vehicle) -> np.ndarray:
    """Everything the compiled right-hand side needs, in one float array (inverse mass matrix last)."""
    v = vehicle
    mass = v.mass_kg
    r2, r3, r4, r5 = (v.scale(n) for n in (2, 3, 4, 5))
    mass_matrix = np.array(
        [
            [mass - r3 * v.coefficient("X_udot"), 0.0, 0.0],
            [0.0, mass - r3 * v.coefficient("Z_wdot"), -r4 * v.coefficient("Z_qdot")],
            [0.0, -r4 * v.coefficient("M_wdot"), v.iy_kg_m2 - r5 * v.coefficient("M_qdot")],
        ]
    )
    head = [mass, v.weight_n, v.buoyancy_n, v.bg_m, v.thrust_n, r2, r3, r4, r5, v.plane_time_constant_s]
    derivs = [v.coefficient(n) for n in _PARAM_DERIVATIVES]
    return np.array(head + derivs + list(np.linalg.inv(mass_matrix).ravel()), dtype=float)


@njit(cache=True)
def _rhs(
    p: np.ndarray, s: np.ndarray, delta: float, command: float
) -> np.ndarray:  # pragma: no cover - compiled
    u, w, q, theta = s[0], s[1], s[2], s[3]
    mass, weight, buoy, bg, thrust = p[0], p[1], p[2], p[3], p[4]
    r2, r3, r4, r5, servo = p[5], p[6], p[7], p[8], p[9]
    xwq, xuu, xdd, zuq, zuu, zuw, zww, zds = p[10], p[11], p[12], p[13], p[14], p[15], p[16], p[17]
    mqq, muq, muu, muw, mww, mds = p[18], p[19], p[20], p[21], p[22], p[23]
    sin_t, cos_t = np.sin(theta), np.cos(theta)
    fx = (
        -mass * w * q
        + r3 * xwq * w * q
        + r2 * (xuu * u * abs(u) + xdd * u * u * delta * delta)
        + thrust
        - (weight - buoy) * sin_t
    )
    fz = (
        mass * u * q
        + r3 * zuq * u * q
        + r2 * (zuu * u * u + zuw * u * w + zww * w * abs(w) + zds * u * u * delta)
        + (weight - buoy) * cos_t
    )
    fm = (
        r5 * mqq * q * abs(q)
        + r4 * muq * u * q
        + r3 * (muu * u * u + muw * u * w + mww * w * abs(w) + mds * u * u * delta)
        - bg * buoy * sin_t
    )
    out = np.empty(7)
    out[0] = p[24] * fx + p[25] * fz + p[26] * fm
    out[1] = p[27] * fx + p[28] * fz + p[29] * fm
    out[2] = p[30] * fx + p[31] * fz + p[32] * fm
    out[3] = q
    out[4] = -u * sin_t + w * cos_t
    out[5] = u * cos_t + w * sin_t
    out[6] = (command - delta) / servo
    return out


@njit(cache=True)
def _rk4(
    p: np.ndarray,
    s: np.ndarray,
    h: float,
    command: float,
    table_t: np.ndarray,
    table_delta: np.ndarray,
    t0: float,
) -> np.ndarray:  # pragma: no cover - compiled
    """One RK4 step; the plane angle is the servo state, or read from the table when one is given."""
    replay = table_t.size > 0
    k = np.empty((4, 7))
    offsets = (0.0, 0.5 * h, 0.5 * h, h)
    stage = s.copy()
    for i in range(4):
        if i > 0:
            stage = s + offsets[i] * k[i - 1]
        delta = np.interp(t0 + offsets[i], table_t, table_delta) if replay else stage[6]
        k[i] = _rhs(p, stage, delta, command)
        if replay:
            k[i, 6] = 0.0
    new = s + h / 6.0 * (k[0] + 2.0 * k[1] + 2.0 * k[2] + k[3])
    if replay:
        new[6] = np.interp(t0 + h, table_t, table_delta)
    return new


@njit(cache=True)
def _crossing_fraction(
    theta0: float, q0: float, theta1: float, q1: float, h: float, level: float
) -> float:  # pragma: no cover - compiled
    """Where in [0, 1] the cubic Hermite through (theta, q) at both step ends meets ``level``."""
    f = (theta0 - level) / (theta0 - theta1)
    for _ in range(6):
        f2, f3 = f * f, f * f * f
        value = (
            (2 * f3 - 3 * f2 + 1) * theta0
            + (f3 - 2 * f2 + f) * h * q0
            + (-2 * f3 + 3 * f2) * theta1
            + (f3 - f2) * h * q1
        ) - level
        slope = (
            (6 * f2 - 6 * f) * theta0
            + (3 * f2 - 4 * f + 1) * h * q0
            + (-6 * f2 + 6 * f) * theta1
            + (3 * f2 - 2 * f) * h * q1
        )
        if slope == 0.0:
            break
        f = min(max(f - value / slope, 0.0), 1.0)
    return f


@njit(cache=True)
def _integrate(
    p: np.ndarray,
    s0: np.ndarray,
    h: float,
    n_sub: int,
    n_samples: int,
    t_execute: float,
    delta_amp: float,
    theta_switch: float,
    max_switches: int,
    table_t: np.ndarray,
    table_delta: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Fixed-step RK4 with zigzag switching about the initial (trim) state, or replay of a plane table.

    Samples every n_sub steps. The plane command is trim + direction * delta_amp; the switch levels are
    trim pitch -/+ theta_switch. Returns the samples and the switch times (execution first).
    """
    out = np.empty((n_samples, 7))
    switches = np.empty(max_switches + 2)
    n_switch = 0
    s = s0.copy()
    delta_trim, theta_trim = s0[6], s0[3]
    direction = 0.0
    out[0] = s
    zigzag = table_t.size == 0
    t = 0.0
    for k in range(1, n_samples):
        for _ in range(n_sub):
            if zigzag and direction == 0.0 and t >= t_execute - 1e-9:
                direction = 1.0
                switches[n_switch] = t
                n_switch += 1
            command = delta_trim + direction * delta_amp
            new = _rk4(p, s, h, command, table_t, table_delta, t)
            level = theta_trim - direction * theta_switch
            crossed = zigzag and direction != 0.0 and direction * (new[3] - level) <= 0.0
            if crossed:
                f = _crossing_fraction(s[3], s[2], new[3], new[2], h, level)
                mid = _rk4(p, s, f * h, command, table_t, table_delta, t)
                switches[n_switch] = t + f * h
                n_switch += 1
                if n_switch > max_switches + 1:  # execution, max_switches reversals, and this one
                    out[k] = mid
                    return out[: k + 1], switches[:n_switch]
                direction = -direction
                new = _rk4(
                    p, mid, (1.0 - f) * h, delta_trim + direction * delta_amp, table_t, table_delta, t + f * h
                )
            s = new
            t += h
        out[k] = s
    return out, switches[:n_switch]


def _time_step(rate_hz: float, max_step_s: float) -> tuple[float, int]:
    n_sub = max(1, int(np.ceil((1.0 / rate_hz) / max_step_s)))
    return 1.0 / rate_hz / n_sub, n_sub


def trim_state(vehicle: Vehicle) -> np.ndarray:
    """Steady level flight: u, w, theta and plane angle with all accelerations and dz/dt zero.

    A vehicle that is not neutrally buoyant (REMUS: B - W = 9 N) needs a plane angle and some pitch to
    hold depth; the zigzag is then run about this trim, as manoeuvres are in practice.
    """
    params = pack_parameters(vehicle)

    def residual(x: np.ndarray) -> np.ndarray:
        state = np.array([x[0], x[1], 0.0, x[2], 0.0, 0.0, x[3]])
        rates = _rhs(params, state, x[3], x[3])
        return np.array([rates[0], rates[1], rates[2], rates[4]])

    from scipy.optimize import fsolve  # imported here: scipy.optimize is slow to import

    solution, info, ok, _ = fsolve(residual, [vehicle.nominal_speed_m_s, 0.0, 0.0, 0.0], full_output=True)
    if ok != 1 or np.max(np.abs(info["fvec"])) > 1e-8:
        raise InputError(
            f"{vehicle.name}: no steady level flight found at the nominal speed; check the vehicle file"
        )
    u, w, theta, delta = solution
    return np.array([u, w, 0.0, theta, 0.0, 0.0, delta])


def simulate_zigzag(
    vehicle: Vehicle,
    delta_rad: float,
    theta_rad: float,
    switches: int = 8,
    rate_hz: float = 20.0,
    approach_s: float = 5.0,
    max_step_s: float = 0.01,
) -> StateRecord:
    """The zigzag-like diving manoeuvre: plane +delta, switched to -/+delta when pitch reaches -/+theta.

    Angles are about the trim (plane angle and pitch of steady level flight). Runs trimmed for
    ``approach_s``, then executes and stops at the moment of switch number
    ``switches + 1`` (not applied), so the record holds ``switches`` reversals of the plane.
    """
    if not 0 < delta_rad < np.pi / 2 or not 0 < theta_rad < np.pi / 2:
        raise InputError("zigzag angles must be between 0 and 90 deg (e.g. --delta 15 --theta 10)")
    if vehicle.plane_limit_deg is not None and np.degrees(delta_rad) > vehicle.plane_limit_deg + 1e-9:
        raise InputError(
            f"--delta {np.degrees(delta_rad):g} deg exceeds {vehicle.name}'s plane limit "
            f"of {vehicle.plane_limit_deg:g} deg"
        )
    if switches < 1:
        raise InputError("the zigzag needs at least one plane reversal")
    h, n_sub = _time_step(rate_hz, max_step_s)
    n_max = int(MAX_DURATION_S * rate_hz) + 1
    empty = np.empty(0)
    samples, switch_times = _integrate(
        pack_parameters(vehicle),
        trim_state(vehicle),
        h,
        n_sub,
        n_max,
        approach_s,
        delta_rad,
        theta_rad,
        switches,
        empty,
        empty,
    )
    if switch_times.size < switches + 2:
        raise InputError(
            f"{vehicle.name}: pitch did not reach {np.degrees(theta_rad):g} deg often enough within "
            f"{MAX_DURATION_S:g} s with a {np.degrees(delta_rad):g} deg stern plane; "
            "increase --delta or lower --theta"
        )
    samples = samples[:-1]  # the last row is the state at the final (unapplied) switch, off the sample grid
    t = np.arange(samples.shape[0]) / rate_hz
    record = StateRecord(
        t=t, states=dict(zip(STATE_COLUMNS, samples.T, strict=True)), switch_times=switch_times[1:]
    )
    record.meta.update(
        {
            "vehicle": vehicle.name,
            "manoeuvre": "zigzag",
            "delta_deg": f"{np.degrees(delta_rad):g}",
            "theta_deg": f"{np.degrees(theta_rad):g}",
            "switches": str(switches),
            "approach_s": f"{approach_s:g}",
        }
    )
    return record


def replay(
    vehicle: Vehicle, t: np.ndarray, delta_s: np.ndarray, state0: np.ndarray, max_step_s: float = 0.01
) -> StateRecord:
    """Simulate the vehicle driven by a given plane-angle history (validation against a record)."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    if dt.size == 0 or np.any(dt <= 0):
        raise InputError("replay needs at least two samples at increasing times")
    rate_hz = 1.0 / float(np.median(dt))
    h, n_sub = _time_step(rate_hz, max_step_s)
    start = np.asarray(state0, dtype=float).copy()
    start[6] = delta_s[0]
    samples, _ = _integrate(
        pack_parameters(vehicle),
        start,
        h,
        n_sub,
        t.size,
        0.0,
        0.0,
        0.0,
        0,
        t - t[0],
        np.asarray(delta_s, dtype=float),
    )
    grid = t[0] + np.arange(samples.shape[0]) / rate_hz
    states = {c: np.interp(t, grid, samples[:, i]) for i, c in enumerate(STATE_COLUMNS)}
    return StateRecord(t=t.copy(), states=states, meta={"vehicle": vehicle.name, "manoeuvre": "replay"})


#: "Realistic" white sensor noise (1 sigma, SI) at 100 Hz: velocities from a DVL-aided INS (3 mm/s), an
#: MTi-G-class gyro rate (0.002 rad/s = 0.11 deg/s) and pitch (0.002 rad), a pressure depth sensor (1 cm),
#: position (5 cm) and the stern-plane potentiometer (0.002 rad).
REALISTIC_NOISE_STD: dict[str, float] = {
    "u": 0.003,
    "w": 0.003,
    "q": 0.002,
    "theta": 0.002,
    "z": 0.01,
    "x": 0.05,
    "delta_s": 0.002,
}


def add_noise(record: StateRecord, scale: float, seed: int | None = 0) -> StateRecord:
    """A copy with Gaussian noise of ``scale`` times REALISTIC_NOISE_STD on every state column."""
    rng = np.random.default_rng(seed)
    states = {
        c: values + scale * REALISTIC_NOISE_STD[c] * rng.standard_normal(values.size)
        for c, values in record.states.items()
    }
    return StateRecord(
        t=record.t.copy(),
        states=states,
        meta={**record.meta, "noise": f"{scale:g}"},
        switch_times=record.switch_times.copy(),
    )
