"""The discrepancy workflow: fit a baseline, find where it disagrees, name and add the missing effect, repeat.

Decisions are made by output-error refits scored by BIC with a clear margin
(derivative-based screening fails at realistic noise); the residual
diagnostics say why and go into the story. After each addition every candidate
is tried again, because an unmodelled effect biases the terms already in.
A late disturbance (reflected waves) is handled first when its signature is
present, by cutting the records, since no term should be made to fit it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..config.validation import equation_model
from ..errors import BadIdentificationInput, InputError
from ..ident.base import EstimatorMixin
from ..ident.signals import white_noise_level
from ..records import DecayRun
from .effects import LIBRARY, Effect, EffectKind, Family
from .fitting import Fit, ModelSpec, fit_spec, predict
from .residuals import (
    SPECTRUM_MEANING,
    CycleTrend,
    Diagnostics,
    channel_correlation,
    cycle_trend,
    late_onset,
    residual_spectrum,
    ringing_frequency,
)

DEFAULT_BASELINE = "b1,c1"
#: A late burst counts when the residual after the change point is this many times louder than before,
LATE_RATIO = 3.0
#: and the records are cut there only if the model then fits to within this multiple of the noise level.
LATE_QUIET = 1.5
#: Split-sample check: fit the first part of every run, predict the rest.
FIT_FRACTION = 0.6
#: At most this many candidates (best BIC first) are checked on held-out data per step.
MAX_CHECKED = 3


def parse_baseline(text: str) -> tuple[str, ...]:
    """'b1,c1' or an ident alias ('ittc-linear', 'seed001-eq1') -> the canonical terms of the baseline."""
    return equation_model(
        text,
        f"baseline {text!r}: a baseline takes",
        "friction and coupling are effects the workflow adds itself",
    )


@dataclass
class FamilyEvidence:
    """One member of the chosen effect's family, scored against the same starting model."""

    effect: str
    delta_bic: float  # vs the model before the step
    vs_chosen: float  # BIC(member) - BIC(chosen): positive = chosen is better


@dataclass
class Step:
    """One accepted change: an effect added (or the records cut) and the fits around it."""

    effect: Effect
    before: Fit
    after: Fit
    diagnostics: Diagnostics  # of the fit before the step: why this effect
    delta_bic: float | None  # None for truncation (different data, BIC not comparable)
    added: dict[str, float]
    family: list[FamilyEvidence] = field(default_factory=list)
    cut_s: list[float] = field(default_factory=list)
    held_out: tuple[float, float] | None = None  # split-sample RMS before/after, in noise units


def initial_guess(runs: Sequence[DecayRun], terms: Sequence[str]) -> dict[str, float]:
    """Natural frequency from the angle spectrum, damping from the cycle decrement: LM starts near the end."""
    omegas = []
    for run in runs:
        x = run.angle - np.mean(run.angle)
        n_fft = 8 * x.size
        spec = np.abs(np.fft.rfft(x, n_fft))
        freqs = np.fft.rfftfreq(n_fft, 1.0 / run.sample_rate)
        omegas.append(2 * np.pi * freqs[int(np.argmax(spec[1:])) + 1])
    omega = float(np.median(omegas))
    trend = cycle_trend([r.t for r in runs], [r.angle for r in runs], omega)
    zeta = float(np.clip(np.median(trend.zeta), 1e-4, 0.5)) if trend.zeta.size else 0.02
    stiffness = omega**2 / max(1 - zeta**2, 1e-3)
    guess = {"b1": 2 * zeta * np.sqrt(stiffness)}
    guess["s1" if "c1" not in terms and "s1" in terms else "c1"] = stiffness
    return guess


def _cut(runs: Sequence[DecayRun], cut_s: Sequence[float]) -> list[DecayRun]:
    """Each run up to its cut time (from its start)."""
    return [r.window(0, int(np.searchsorted(r.t, r.t[0] + c))) for r, c in zip(runs, cut_s, strict=True)]


def natural_frequency(fit: Fit) -> float:
    stiffness = fit.coefficients.get("c1", 0.0) + fit.coefficients.get("s1", 0.0)
    return float(np.sqrt(max(stiffness, 1e-6)))


def diagnose_fit(fit: Fit, runs: Sequence[DecayRun]) -> Diagnostics:
    """All residual diagnostics of one fit."""
    omega0 = natural_frequency(fit)
    residuals = [p.residual_angle for p in fit.runs]
    noise = float(np.sqrt(np.mean([white_noise_level(r.angle) ** 2 for r in runs])))
    rate_res = [p.residual_rate for p in fit.runs if p.residual_rate is not None]
    e = np.concatenate(residuals)
    corr_rate = float(abs(np.corrcoef(e, np.concatenate([p.rate for p in fit.runs]))[0, 1]))
    corr_angle = float(abs(np.corrcoef(e, np.concatenate([p.angle for p in fit.runs]))[0, 1]))
    channel_corr: dict[str, float] = {}
    shared = set.intersection(*(set(r.channels) for r in runs)) if runs else set()
    for ch in sorted(shared):
        max_lag = int(np.pi / omega0 * runs[0].sample_rate)
        channel_corr[ch] = float(
            np.mean(
                [
                    channel_correlation(p.residual_angle, r.channels[ch], max_lag)
                    for p, r in zip(fit.runs, runs, strict=True)
                ]
            )
        )
    return Diagnostics(
        rms_angle_rad=fit.rms_angle,
        noise_angle_rad=noise,
        ljung_box_p=fit.ljung_box_p,
        spectrum=residual_spectrum(residuals, runs[0].sample_rate, omega0),
        residual_mean_angle_rad=float(np.mean(e)),
        residual_mean_rate_rad_s=float(np.mean(np.concatenate(rate_res))) if rate_res else None,
        noise_rate_rad_s=float(
            np.sqrt(np.mean([white_noise_level(r.rate) ** 2 for r in runs if r.rate is not None]))
        )
        if rate_res
        else None,
        corr_with_rate=0.0 if np.isnan(corr_rate) else corr_rate,
        corr_with_angle=0.0 if np.isnan(corr_angle) else corr_angle,
        channel_corr=channel_corr,
        late=[late_onset(p.t, p.residual_angle) for p in fit.runs],
        ringing_rad_s=ringing_frequency(residuals, runs[0].sample_rate, omega0),
    )


def signature_seen(effect: Effect, diag: Diagnostics, trend: CycleTrend) -> list[str]:
    """What the diagnostics before a step show of the effect's signature (empty: nothing evident).

    The decision is the refit's; this is the why a person can check on the plots.
    """
    seen: list[str] = []
    spectrum = diag.spectrum.location
    if effect.family == Family.AMPLITUDE_DAMPING and trend.damping_grows_with_amplitude:
        seen.append(f"damping ratio grows with amplitude ({trend.zeta_slope_per_rad:.3f} per rad)")
    if effect.family == Family.DRY_FRICTION and trend.damping_falls_with_amplitude:
        seen.append(f"damping ratio falls with amplitude ({trend.zeta_slope_per_rad:.3f} per rad)")
    if effect.family == Family.NONLINEAR_RESTORING:
        if trend.period_changes_with_amplitude:
            seen.append(f"period changes with amplitude ({trend.period_slope_s_per_rad2:.3f} s per rad^2)")
        if spectrum == "triple":
            seen.append("residual peak at three times the natural frequency")
    if effect.family == Family.OFFSET_OR_ASYMMETRY:
        if spectrum in ("zero", "double"):
            seen.append(SPECTRUM_MEANING[spectrum])
        if abs(diag.residual_mean_angle_rad) > 0.5 * diag.noise_angle_rad:
            seen.append(f"angle residual mean {np.degrees(diag.residual_mean_angle_rad):.3f} deg")
    bias = diag.residual_mean_rate_rad_s
    if (
        effect.key == "sensor.gyro_bias"
        and bias is not None
        and abs(bias) > 0.5 * (diag.noise_rate_rad_s or 0)
    ):
        seen.append(f"rate residual mean {np.degrees(bias):.3f} deg/s")
    if effect.key == "sensor.lag" and diag.corr_with_rate > 0.5:
        seen.append(f"angle residual follows the rate (correlation {diag.corr_with_rate:.2f})")
    if effect.key == "sensor.gain" and diag.corr_with_angle > 0.5:
        seen.append(f"angle residual follows the angle (correlation {diag.corr_with_angle:.2f})")
    if effect.family == Family.COUPLED_MOTION:
        seen += [f"residual correlated with {ch} ({c:.2f})" for ch, c in diag.channel_corr.items() if c > 0.3]
        if spectrum == "other":
            seen.append(f"residual peak at {diag.spectrum.peak_rad_s:.2f} rad/s, not a harmonic")
    if effect.kind == EffectKind.TRUNCATION:
        burst = [o for o in diag.late if o.ratio > LATE_RATIO]
        seen += [f"residual {o.ratio:.1f}x louder after {o.onset_s:.1f} s" for o in burst]
    return seen


class Diagnoser(EstimatorMixin):
    """Find what a decay model is missing, add it, and show the gap shrink.

    ``Diagnoser(baseline="b1,c1").fit(runs)`` sets ``baseline_``, ``steps_``,
    ``final_`` (Fit objects), ``cycle_trend_`` (model-free amplitude trends),
    ``runs_`` (the records as finally used, cut if a late disturbance was found),
    ``verdict_`` and ``gap_reduction_``.
    """

    def __init__(
        self,
        baseline: str | Sequence[str] = DEFAULT_BASELINE,
        max_steps: int = 4,
        delta_bic: float = -10.0,
        library: Sequence[Effect] = LIBRARY,
        progress: Callable[[str], None] | None = None,
    ):
        self.baseline = baseline
        self.max_steps = max_steps
        self.delta_bic = delta_bic
        self.library = library
        self.progress = progress

    def _fit(self, runs: Sequence[DecayRun], spec: ModelSpec, label: str, **kwargs: object) -> Fit:
        if self.progress is not None:
            self.progress(label)
        return fit_spec(runs, spec, **kwargs)  # type: ignore[arg-type]

    def fit(self, runs: Sequence[DecayRun]) -> Diagnoser:
        if not runs:
            raise BadIdentificationInput("no decay runs to diagnose")
        if self.max_steps < 0:
            raise InputError(f"--max-steps must be 0 or more, not {self.max_steps}")
        axes = {r.axis for r in runs}
        if len(axes) > 1:
            raise BadIdentificationInput(f"runs mix axes {sorted(axes)}; diagnose one axis at a time")
        terms = parse_baseline(self.baseline) if isinstance(self.baseline, str) else tuple(self.baseline)
        runs = list(runs)
        spec = ModelSpec(terms=terms)
        current = self._fit(runs, spec, "baseline", guess=initial_guess(runs, terms))
        self.baseline_ = current
        self.cycle_trend_: CycleTrend = cycle_trend(
            [r.t for r in runs], [r.angle for r in runs], natural_frequency(current)
        )
        self.steps_: list[Step] = []
        self.diagnostics_: list[Diagnostics] = []
        while len(self.steps_) < self.max_steps:
            diag = diagnose_fit(current, runs)
            self.diagnostics_.append(diag)
            step = self._best_addition(current, runs, diag)
            explains_all = step is not None and step.after.rms_angle <= LATE_QUIET * diag.noise_angle_rad
            if not explains_all and not self._was_truncated():
                truncated = self._truncate(current, runs, diag, step)
                if truncated is not None:
                    runs, step = truncated
            if step is None:
                break
            self.steps_.append(step)
            current = step.after
        else:
            self.diagnostics_.append(diagnose_fit(current, runs))
        self.final_ = current
        self.runs_ = runs
        self.gap_reduction_ = 1.0 - self.final_.rms_angle / self.baseline_.rms_angle
        self.verdict_ = self._verdict()
        return self

    def _was_truncated(self) -> bool:
        return any(s.effect.kind == EffectKind.TRUNCATION for s in self.steps_)

    def _truncate(
        self, current: Fit, runs: list[DecayRun], diag: Diagnostics, best: Step | None
    ) -> tuple[list[DecayRun], Step] | None:
        """Cut the records where the residual turns from noise into a burst, if that is what it does.

        The fit to the whole record is bent by the burst, so the onset is found
        twice: roughly on its residual, then on the residual of a model fitted
        before the rough onset and simulated over the whole record. The cut is
        kept when the model fits the rest to the noise level, the burst is loud,
        and the best added term would not have explained it.
        """
        effect = next((e for e in self.library if e.kind == EffectKind.TRUNCATION), None)
        if effect is None:
            return None
        noise = diag.noise_angle_rad
        early = self._fit(
            _cut(runs, [o.onset_s for o in diag.late]), current.spec, "early refit", start=current
        )
        onsets = [late_onset(p.t, p.residual_angle) for p in predict(early, runs)]
        if not all(o.ratio > LATE_RATIO for o in onsets):
            return None
        if best is not None:
            late_rms = [
                float(np.sqrt(np.mean(p.residual_angle[p.t - p.t[0] >= o.onset_s] ** 2)))
                for p, o in zip(best.after.runs, onsets, strict=True)
            ]
            if min(late_rms) <= 2 * noise:
                return None
        quarter_period_s = 0.5 * np.pi / natural_frequency(current)
        cut_s = [o.onset_s - quarter_period_s for o in onsets]
        cut_runs = _cut(runs, cut_s)
        after = self._fit(cut_runs, current.spec, "truncated refit", start=early)
        if after.rms_angle > LATE_QUIET * noise:
            return None
        return cut_runs, Step(effect, current, after, diag, None, {}, cut_s=cut_s)

    def _best_addition(self, current: Fit, runs: list[DecayRun], diag: Diagnostics) -> Step | None:
        """Refit every applicable candidate; keep the best that beats the BIC margin and predicts better.

        BIC on a coloured residual is over-confident (on real records every term
        passes by thousands), so a candidate must also predict the held-out last
        part of every run better than the model without it.
        """
        scored: list[tuple[Effect, Fit, float]] = []
        for effect in self.library:
            spec = effect.extend(current.spec, runs, diag)
            if spec is None:
                continue
            candidate = self._fit(runs, spec, effect.name, start=current, guess=ringing_guess(diag))
            if effect.plausible(candidate):
                scored.append((effect, candidate, candidate.bic - current.bic))
        passing = sorted((item for item in scored if item[2] < self.delta_bic), key=lambda item: item[2])
        if not passing:
            return None
        held_before = self._held_out_rms(runs, current.spec, current, diag)
        for effect, best, delta in passing[:MAX_CHECKED]:
            held_after = self._held_out_rms(runs, best.spec, best, diag)
            if held_after < held_before:
                family = [
                    FamilyEvidence(e.key, d, f.bic - best.bic)
                    for e, f, d in scored
                    if e.family == effect.family and e is not effect
                ]
                step = Step(effect, current, best, diag, delta, _added(current, best), family)
                step.held_out = (held_before, held_after)
                return step
        return None

    def _held_out_rms(self, runs: list[DecayRun], spec: ModelSpec, start: Fit, diag: Diagnostics) -> float:
        """RMS of all outputs (noise units) on the last part of every run, from a fit to the first part."""
        first = _cut(runs, [FIT_FRACTION * r.duration for r in runs])
        fit = self._fit(first, spec, "split-sample check", start=start, guess=ringing_guess(diag))
        squares: list[np.ndarray] = []
        for part, whole, pred in zip(first, runs, predict(fit, runs), strict=True):
            held = slice(part.t.size, None)
            squares.append((pred.residual_angle[held] / max(white_noise_level(whole.angle), 1e-12)) ** 2)
            if pred.residual_rate is not None and whole.rate is not None:
                squares.append((pred.residual_rate[held] / max(white_noise_level(whole.rate), 1e-12)) ** 2)
        return float(np.sqrt(np.mean(np.concatenate(squares))))

    def _verdict(self) -> str:
        added = [s.effect for s in self.steps_]
        white = self.diagnostics_[-1].white if self.diagnostics_ else False
        if not added:
            if white:
                return "nothing missing: the baseline model explains the decays to the noise level"
            return (
                "nothing in the library improves the model clearly, yet the residual is not white: "
                "an effect outside the library"
            )
        names = "; ".join(f"{e.name} ({e.family})" for e in added)
        tail = "residual white" if white else "residual still not white, something remains"
        return f"missing: {names}; gap reduced by {100 * self.gap_reduction_:.0f} %; {tail}"


def ringing_guess(diag: Diagnostics) -> dict[str, float]:
    """Start of an unmeasured ringing: the residual's frequency, decaying over about ten periods."""
    if diag.ringing_rad_s is None:
        return {}
    return {"ring_omega_rad_s": diag.ringing_rad_s, "ring_decay_1_s": diag.ringing_rad_s / (20 * np.pi)}


def _added(before: Fit, after: Fit) -> dict[str, float]:
    """Parameters the step brought in (the per-run angle offset as its mean)."""
    added = {k: v for k, v in after.coefficients.items() if k not in before.coefficients}
    if after.offsets and not before.offsets:
        added["angle_offset_rad"] = float(np.mean(after.offsets))
    return added
