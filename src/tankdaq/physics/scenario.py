"""A scripted, hand-operated decay test with known truth, and the sensor that watches it.

A towing-tank decay test is not a clean initial-value problem: the model rests in still
water, an engineer tilts it by hand (a smooth 1-2 s push), holds it for a few seconds with a
trembling hand, lets go, and the model decays back to rest. Release detection, the recorder
and the estimators are tested against exactly this, so the scenario produces:

- the true motion of the sensed axis (angle, rate, acceleration) plus a little cross-axis and
  heave motion, on the device clock (SampleTimeFine, 10 kHz ticks);
- the truth of every run: release instant (s, ticks, first free sample), initial state,
  model terms and coefficients;
- sensor samples (``SAMPLE_DTYPE``) with MTi-G-like noise, bias and quantisation on top
  (``physics.sensor``; the trace and the truth are ``physics.truth``).

Everything is vectorised and seeded: an hour of still water and handling takes well under a
second per hour of 100 Hz data apart from the decay integrations themselves.
"""

from __future__ import annotations

import dataclasses
import math
import secrets
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .decay import acceleration, decay_refusal, simulate_decay
from .sensor import SensorModel, SensorNoise
from .truth import TICK_MODULUS, TICKS_PER_S, RunKind, RunTruth, ScenarioTrace

#: A fresh seed is below this: short enough to read off a file and type again after ``--seed``.
FRESH_SEED_BELOW = 2**32


def fresh_seed(seed: int | None = None) -> int:
    """``seed`` when given (the same test again), else a new one from the OS: every simulated test
    differs from the last unless asked, so two of its files never hold the same decay."""
    return secrets.randbelow(FRESH_SEED_BELOW) if seed is None else seed


#: The release falls this much (uniformly) after the scripted instant: off the sample grid at any rate.
RELEASE_JITTER_S = 0.01

#: A run scripted to push again gets its second push this long after the release: two cycles or so.
PUSH_AGAIN_AFTER_S = 3.0
#: The second push brings the amplitude back to this fraction of the initial angle.
PUSH_AGAIN_FRACTION = 0.8
#: What a scripted campaign run can do wrong (``scripted_run``): the hand tilts to the wrong angle,
#: pushes the model again mid-decay (the release is not clean), shoves it to its angle so hard that the
#: gyro clips during the push (harmless: the decay is clean), the gyro's range is so small that the
#: first swings of the decay clip (the decay must be rejected), someone knocks the model at rest
#: shortly before the tilt (a bump it has not settled from when it is tilted and released), or the
#: still water creeps away from level before the tilt (a drift: the model heels on, and decays about its
#: new rest).
SCRIPTED_FAULTS = ("wrong-angle", "double-push", "hard-push", "clipped-decay", "bump", "drift")
#: A bumped run is knocked this long before its tilt begins (s): still swinging when the hand takes it;
#: its tilt begins this much later than a clean run's (``release_after_s`` longer), after still water.
BUMP_BEFORE_TILT_S = 3.5
#: The knock sets the model swinging about its rest angle with this amplitude (deg): well above still
#: water, below the release detector's tilt threshold (1.5 deg).
BUMP_DEG = 1.0
#: A drifting run's still water creeps at this rate (deg/min, towards positive angles) for
#: ``DRIFT_BEFORE_TILT_S`` before its tilt, then stays there: a model taking on water (1 L/min 0.3 m off
#: the centreline of a 50 kg model with GM 0.1 m heels it 3.4 deg/min) or a trim weight sliding.
DRIFT_DEG_MIN = 3.0
#: How long a drifting run's still water creeps before its tilt (s): 1.5 deg at ``DRIFT_DEG_MIN``, past a
#: plan's usual 1 deg level tolerance after 20 s; its tilt begins this much later than a clean run's.
DRIFT_BEFORE_TILT_S = 30.0
#: A hard push reaches its angle at this mean rate (deg/s): its peak, 1.9 times more, clips a 300 deg/s gyro.
HARD_PUSH_DEG_S = 250.0
#: A clipped-decay run's gyro range per degree of release angle (deg/s per deg): below the first swings'
#: peak rate for a lightly damped model with a period under about 3 s (omega x0 > 2 x0).
CLIPPED_RANGE_PER_DEG = 2.0
#: A wrong-angle run is tilted this much further than asked.
WRONG_ANGLE_FACTOR = 1.5

#: What a hull's ``[simulation]`` part must give (the start of the line that refuses one).
SIMULATION_RULE = (
    "the simulator's coefficients must give a decay (damped, finite, positive stiffness, a period the "
    "simulator can play)"
)


#: A swaying hold (``Handling.swaying``): the hand sways slowly, (amplitude deg, frequency Hz) at random
#: phases, so the model leaves the hand with a rate and an acceleration that are not zero (issue 38).
SWAY_LINES = ((0.15, 0.9), (0.05, 2.3))


@dataclass(frozen=True)
class Handling:
    """How the engineer handles the model: timings (s) and hand tremor.

    The hand's sway (0.1-0.8 Hz, ``sway_deg`` rms; plus ``sway_lines``, sinusoids of given amplitude (deg)
    and frequency (Hz) at random phases: ``swaying()``) and physiological tremor (8-12 Hz,
    ``tremor_deg`` rms) act during the tilt and the hold and stop at release. The default is a still
    hold; a swaying one moves a release found by a smooth hold model by several samples. Tremor reaches a
    floating model as a force: ~1 % of the ~0.6 N holding force at 0.3 m is 2e-3 N m, which a
    0.12 kg m^2 model at 10 Hz turns into ~4e-4 deg, so 0.001 deg is on the generous side; the model then
    starts from the hand's angle *and rate*, as in a real release. A fraction
    ``put_back_fraction`` of runs are aborted: held, then lowered back by hand with no release.
    """

    tilt_s: tuple[float, float] = (1.0, 2.0)
    hold_s: tuple[float, float] = (2.5, 5.0)
    angle_scatter_deg: float = 0.3
    sway_deg: float = 0.08
    tremor_deg: float = 0.001
    put_back_s: tuple[float, float] = (1.5, 2.5)
    put_back_fraction: float = 0.0
    lead_in_s: float = 1.0
    sway_lines: tuple[tuple[float, float], ...] = ()

    @classmethod
    def swaying(cls, **settings: object) -> Handling:
        """A swaying hold: ``SWAY_LINES`` instead of the band's sway (the still hold's other settings)."""
        return cls(**{"sway_deg": 0.0, "sway_lines": SWAY_LINES, **settings})  # type: ignore[arg-type]


def _quintic_step(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothstep 10s^3-15s^4+6s^5 on [0, 1] and its first two derivatives (d/ds)."""
    s = np.clip(s, 0.0, 1.0)
    return (
        s**3 * (10 - 15 * s + 6 * s**2),
        30 * s**2 * (1 - s) ** 2,
        60 * s * (1 - s) * (1 - 2 * s),
    )


@dataclass(frozen=True)
class _Wobble:
    """A random sum of sinusoids in a band: the hand's sway or tremor, evaluated at any time."""

    freqs_hz: np.ndarray
    phases: np.ndarray
    amps: np.ndarray

    @classmethod
    def draw(
        cls, rng: np.random.Generator, rms: float, band_hz: tuple[float, float], count: int = 5
    ) -> _Wobble:
        amps = rng.uniform(0.5, 1.0, count)
        amps *= rms * math.sqrt(2) / np.sqrt(np.sum(amps**2))
        return cls(rng.uniform(*band_hz, count), rng.uniform(0, 2 * np.pi, count), amps)

    @classmethod
    def lines(cls, rng: np.random.Generator, lines: tuple[tuple[float, float], ...]) -> _Wobble:
        """Sinusoids of given (amplitude, frequency Hz) at random phases."""
        amps, freqs = (np.array([line[k] for line in lines], dtype=float) for k in (0, 1))
        return cls(freqs, rng.uniform(0, 2 * np.pi, len(lines)), amps)

    def __add__(self, other: _Wobble) -> _Wobble:
        mine, theirs = (self.freqs_hz, self.phases, self.amps), (other.freqs_hz, other.phases, other.amps)
        return _Wobble(*(np.concatenate(pair) for pair in zip(mine, theirs, strict=True)))

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Value and time derivative at t."""
        omega = 2 * np.pi * self.freqs_hz
        arg = omega[None, :] * t[:, None] + self.phases[None, :]
        return np.sin(arg) @ self.amps, np.cos(arg) @ (self.amps * omega)


def valid_rate(rate_hz: float) -> float:
    """Refuse output rates the 10 kHz SampleTimeFine clock cannot tick evenly (MTi rates divide 400 Hz)."""
    if not (rate_hz > 0 and TICKS_PER_S % rate_hz == 0 and rate_hz <= 2000):
        raise InputError(
            f"rate {rate_hz:g} Hz is not an MTi output rate; use a divisor of 400 Hz, e.g. 100, 200, 400"
        )
    return float(rate_hz)


@dataclass
class DecayScenario:
    """N hand-operated decay runs of one axis of one hull, deterministic given ``seed``.

    Each run lasts ``release_after_s + decay_s``: still water, a tilt to about ``angle_deg``
    (random sign), a hold with tremor, the release ``release_after_s`` (plus up to 10 ms) after
    the run starts, and a free decay by ``physics.decay`` that carries on into the next run's still water.
    ``coefficients`` are the decay equation's terms the model follows (``hull``/``draft`` only label
    the data); ``config.hull_scenario`` reads them from a hull's ``[simulation]`` part.
    """

    hull: str = "swath"
    draft: float = 1.0
    axis: str = "roll"
    angle_deg: float = 8.0
    rate_hz: float = 100.0
    runs: int = 1
    seed: int = 0
    release_after_s: float = 10.0
    decay_s: float = 25.0
    handling: Handling = field(default_factory=Handling)
    noise: SensorNoise = field(default_factory=SensorNoise)
    coefficients: dict[str, float] = field(kw_only=True)
    start_ticks: int | None = None  # SampleTimeFine of the first sample (near 2**32: a 600's clock wraps)
    start_counter: int | None = None  # PacketCounter of the first sample (near 65535: about to wrap)
    pushes_again: tuple[int, ...] = ()  # runs (from 0) in which the hand pushes the model again mid-decay
    bumps_before: tuple[int, ...] = ()  # runs (from 0) whose model is knocked at rest before the tilt
    drifts_before: tuple[int, ...] = ()  # runs (from 0) whose still water creeps before the tilt
    bias_seed: int | None = None  # the seed of the sensor's biases (None: ``seed``): one device, one bias

    def __post_init__(self) -> None:
        if self.axis not in ("roll", "pitch"):
            raise InputError(f"axis {self.axis!r} not understood; use roll or pitch")
        self.rate_hz = valid_rate(self.rate_hz)
        if not 0.5 <= abs(self.angle_deg) <= 30:
            raise InputError(f"angle {self.angle_deg:g} deg is outside 0.5..30 deg")
        if self.runs < 0:
            raise InputError(f"runs must be >= 0, got {self.runs}")
        shortest = self.handling.lead_in_s + self.handling.tilt_s[1] + 0.5
        if self.release_after_s < shortest:
            raise InputError(
                f"release-after {self.release_after_s:g} s is too short to tilt and hold; use >= {shortest:g}"
            )
        if self.decay_s <= 0:
            raise InputError("decay time must be positive")
        why = decay_refusal(self.coefficients, self.rate_hz)  # before a thread integrates them
        if why is not None:
            raise InputError(f"{self.hull} {self.axis}: {SIMULATION_RULE}: {why}")
        if self.start_ticks is None:
            self.start_ticks = int(np.random.default_rng([self.seed, 1]).integers(0, TICK_MODULUS // 2))
        if self.start_ticks < 0:
            raise InputError(f"start ticks {self.start_ticks} is negative; SampleTimeFine counts from 0")
        if self.start_counter is None:
            self.start_counter = self.seed & 0xFFFF
        if not 0 <= self.start_counter <= 0xFFFF:
            raise InputError(f"start counter {self.start_counter} is outside PacketCounter's 0..65535")

    @property
    def run_s(self) -> float:
        return self.release_after_s + self.decay_s

    @property
    def duration_s(self) -> float:
        return self.runs * self.run_s

    def trace(self) -> ScenarioTrace:
        """The true motion of all runs on the sample grid."""
        rng = np.random.default_rng([self.seed, 2])
        n = round(self.duration_s * self.rate_hz)
        t = np.arange(n) / self.rate_hz
        x, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        coeffs = dict(self.coefficients)
        truths: list[RunTruth] = []
        hands = self._draw_hands(rng)
        tilt_starts = [hand.start_s for _, hand, _ in hands] + [self.duration_s]
        index = self._first_index_at
        rest = 0.0  # the still water's angle (rad): a drift moves it for good, the decays settle about it
        for run, (release, hand, put_back_s) in enumerate(hands):
            i_tilt, i_release = index(hand.start_s), index(release)
            if run in self.bumps_before:
                self._bump(coeffs, t, (x, v, a), index(hand.start_s - BUMP_BEFORE_TILT_S), i_tilt)
            if run in self.drifts_before:
                rest += _drift(t, (x, v), index(hand.start_s - DRIFT_BEFORE_TILT_S), i_tilt)
            held = slice(i_tilt, i_release)
            base = x[i_tilt - 1] if i_tilt > 0 else 0.0  # the rest angle the tilt starts from
            x[held], v[held], a[held] = hand(t[held], base)
            x0, v0 = (float(q[0]) for q in hand(np.array([release]), base)[:2])
            free = slice(i_release, index(tilt_starts[run + 1]))
            run_end = (run + 1) * self.run_s
            if put_back_s is not None:
                step, dstep, ddstep = _quintic_step((t[free] - release) / put_back_s)
                x[free] = rest + (x0 - rest) * (1 - step)
                v[free] = -(x0 - rest) * dstep / put_back_s
                a[free] = -(x0 - rest) * ddstep / put_back_s**2
                truths.append(RunTruth(run, RunKind.PUT_BACK, self.axis, hand.start_s, end_s=run_end))
                continue
            # Integrated from the off-grid release instant (the first point is the release itself), about
            # the rest angle: a heeling moment shifts the equilibrium (its small change of the restoring
            # curve's shape is left out).
            times = np.concatenate(([release], t[free]))
            free_x, free_v = simulate_decay(coeffs, times, x0 - rest, v0)
            x[free], v[free] = free_x[1:], free_v[1:]
            pushed_s = release + PUSH_AGAIN_AFTER_S if run in self.pushes_again else None
            if pushed_s is not None:
                self._push_again(coeffs, t, x, v, index(pushed_s), free.stop, x0 - rest)
            a[free] = acceleration(coeffs, x[free], v[free])
            x[free] += rest
            ticks = (int(self.start_ticks or 0) + round(release * TICKS_PER_S)) % TICK_MODULUS
            truths.append(
                RunTruth(
                    run,
                    RunKind.RELEASE,
                    self.axis,
                    hand.start_s,
                    release,
                    ticks,
                    i_release,
                    x0,
                    v0,
                    run_end,
                    coeffs,
                    pushed_s,
                )
            )
        # Cross-axis: a small coupled share of the motion plus a trim; heave: the hull sinks when heeled.
        cross_share, trim_rad, heave_m_rad2 = 0.03, math.radians(0.3), 0.02
        return ScenarioTrace(
            rate_hz=self.rate_hz,
            axis=self.axis,
            start_ticks=int(self.start_ticks or 0),
            t=t,
            angle=x,
            rate=v,
            acc=a,
            other_angle=trim_rad + cross_share * x,
            other_rate=cross_share * v,
            heave_m=-heave_m_rad2 * x**2,
            heave_acc_m_s2=-2 * heave_m_rad2 * (v**2 + x * a),
            runs=truths,
        )

    def _draw_hands(self, rng: np.random.Generator) -> list[tuple[float, _Hand, float | None]]:
        """(release instant, the hand, put-back duration or None) of every run, drawn in run order so the
        random stream (and so the truth) is the same whatever is done with it afterwards."""
        h = self.handling
        hands = []
        for run in range(self.runs):
            tilt_s = rng.uniform(*h.tilt_s)
            hold_s = min(rng.uniform(*h.hold_s), self.release_after_s - tilt_s - h.lead_in_s)
            # The hand lets go between samples: a jitter independent of the rate keeps the truth
            # (in s and ticks) the same whatever output rate the device is configured to.
            release = run * self.run_s + self.release_after_s + rng.uniform(0, RELEASE_JITTER_S)
            sign = 1.0 if rng.uniform() < 0.5 else -1.0
            target = sign * math.radians(abs(self.angle_deg) + rng.normal(0, h.angle_scatter_deg))
            hand = _Hand(
                release - hold_s - tilt_s,
                tilt_s,
                target,
                _Wobble.draw(rng, h.sway_deg, (0.1, 0.8)),
                _Wobble.draw(rng, h.tremor_deg, (8.0, 12.0)),
            )
            put_back_s = rng.uniform(*h.put_back_s) if rng.uniform() < h.put_back_fraction else None
            if h.sway_lines:  # drawn last: a still hold's random stream (and truth) is as it always was
                hand = dataclasses.replace(hand, sway=hand.sway + _Wobble.lines(rng, h.sway_lines))
            hands.append((release, hand, put_back_s))
        return hands

    @staticmethod
    def _push_again(
        coeffs: dict[str, float],
        t: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        start: int,
        stop: int,
        x0: float,
    ) -> None:
        """The hand pushes the swinging model again at sample ``start``: the rate jumps (in the direction
        of motion) enough to bring the amplitude back near ``PUSH_AGAIN_FRACTION`` of ``x0``, then the
        model decays freely again up to ``stop``."""
        if not 0 < start < stop:
            return
        omega = math.sqrt(max(coeffs.get("c1", 1.0), 1e-6))
        before = start - 1
        kick = math.copysign(PUSH_AGAIN_FRACTION * abs(x0) * omega, v[before] or 1.0)
        again_x, again_v = simulate_decay(coeffs, t[before:stop], float(x[before]), float(v[before]) + kick)
        x[start:stop], v[start:stop] = again_x[1:], again_v[1:]

    @staticmethod
    def _bump(
        coeffs: dict[str, float],
        t: np.ndarray,
        motion: tuple[np.ndarray, np.ndarray, np.ndarray],
        start: int,
        stop: int,
    ) -> None:
        """Someone knocks the model at sample ``start``: the rate jumps by what swings it ``BUMP_DEG``, and it
        swings freely up to ``stop`` (where the hand takes it for the tilt)."""
        if not 0 < start < stop:
            return
        x, v, a = motion
        before = start - 1
        kick = math.radians(BUMP_DEG) * math.sqrt(max(coeffs.get("c1", 1.0), 1e-6))
        bump_x, bump_v = simulate_decay(coeffs, t[before:stop], float(x[before]), float(v[before]) + kick)
        x[start:stop], v[start:stop] = bump_x[1:], bump_v[1:]
        a[start:stop] = acceleration(coeffs, x[start:stop], v[start:stop])

    @property
    def sensor_bias_seed(self) -> int:
        """The seed the sensor's biases follow: ``bias_seed``, else the seed."""
        return self.seed if self.bias_seed is None else self.bias_seed

    def sensor(self) -> SensorModel:
        """The scenario's sensor (its biases follow ``sensor_bias_seed``; its noise the seed)."""
        return SensorModel(
            self.noise, self.rate_hz, self.seed, int(self.start_counter or 0), self.sensor_bias_seed
        )

    def samples(self) -> tuple[np.ndarray, ScenarioTrace]:
        """Measured samples of all runs, and the trace they measure (the truth)."""
        trace = self.trace()
        return self.sensor().measure(trace), trace

    def _first_index_at(self, time_s: float) -> int:
        """Index of the first sample at or after ``time_s``."""
        return min(math.ceil(time_s * self.rate_hz - 1e-9), round(self.duration_s * self.rate_hz))


def _drift(t: np.ndarray, motion: tuple[np.ndarray, np.ndarray], start: int, stop: int) -> float:
    """The still water creeps at ``DRIFT_DEG_MIN`` from sample ``start`` up to ``stop`` (the tilt; slow
    beside the model's period: no swing); returns how far it moved (rad), where the model now rests."""
    if not 0 < start < stop:
        return 0.0
    x, v = motion
    rate_rad_s = math.radians(DRIFT_DEG_MIN) / 60.0
    x[start:stop] += rate_rad_s * (t[start:stop] - t[start])
    v[start:stop] += rate_rad_s
    return rate_rad_s * float(t[stop - 1] - t[start])


@dataclass(frozen=True)
class _Hand:
    """The engineer's hand: a smooth tilt from the rest angle to ``target``, then a hold with wobble."""

    start_s: float
    tilt_s: float
    target: float
    sway: _Wobble
    tremor: _Wobble

    def __call__(self, t: np.ndarray, base: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angle, rate and acceleration at t (the wobble's own acceleration is left out: it only reaches the
        accelerometers, through the lever arm, and is small there)."""
        s, ds, dds = _quintic_step((t - self.start_s) / self.tilt_s)
        grip_time = 0.5 * self.tilt_s  # the hand's wobble fades in during the first half of the tilt
        grip, dgrip, _ = _quintic_step((t - self.start_s) / grip_time)
        sway_x, sway_v = self.sway(t)
        trem_x, trem_v = self.tremor(t)
        wobble_x, wobble_v = np.radians(sway_x + trem_x), np.radians(sway_v + trem_v)
        span = self.target - base
        x = base + span * s + grip * wobble_x
        v = span * ds / self.tilt_s + grip * wobble_v + dgrip / grip_time * wobble_x
        return x, v, span * dds / self.tilt_s**2


def scripted_run(fault: str | None, angle_deg: float) -> dict[str, object]:
    """``DecayScenario`` settings of one run of a scripted campaign at ``angle_deg``: a clean run
    (``fault`` None), or one of ``SCRIPTED_FAULTS`` (the checks of a test session must catch it)."""
    if fault is None:
        return {"angle_deg": angle_deg}
    if fault == "wrong-angle":
        return {"angle_deg": min(angle_deg * WRONG_ANGLE_FACTOR, 30.0)}
    if fault == "double-push":
        return {"angle_deg": angle_deg, "pushes_again": (0,)}
    if fault == "bump":
        return {"angle_deg": angle_deg, "bumps_before": (0,), "release_after_s": 10.0 + BUMP_BEFORE_TILT_S}
    if fault == "drift":
        return {"angle_deg": angle_deg, "drifts_before": (0,), "release_after_s": 10.0 + DRIFT_BEFORE_TILT_S}
    if fault == "hard-push":
        shove_s = abs(angle_deg) / HARD_PUSH_DEG_S
        return {"angle_deg": angle_deg, "handling": Handling(tilt_s=(shove_s, shove_s))}
    if fault == "clipped-decay":
        return {
            "angle_deg": angle_deg,
            "noise": SensorNoise(gyro_range_deg_s=CLIPPED_RANGE_PER_DEG * abs(angle_deg)),
        }
    raise InputError(f"scripted fault {fault!r} not understood; use {' or '.join(SCRIPTED_FAULTS)}")


def parse_fault_script(text: str) -> dict[int, str]:
    """``"2:wrong-angle,5:double-push"`` -> {2: "wrong-angle", 5: "double-push"}: which decays of a
    simulated session (counted from 1) go wrong, and how."""
    script: dict[int, str] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        number, _, fault = item.partition(":")
        if not number.isdigit() or int(number) < 1 or fault not in SCRIPTED_FAULTS:
            raise InputError(
                f"fault script item {item!r} not understood: write DECAY:FAULT, e.g. 2:wrong-angle, "
                f"with FAULT one of {', '.join(SCRIPTED_FAULTS)}"
            )
        script[int(number)] = fault
    return script
