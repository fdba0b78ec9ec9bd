# SPDX-License-Identifier: Apache-2.0
"""
Every tuning number of the Kalman deflection estimator, named, with its unit and its reason.

:data:`SETTINGS` is the one table: name, default, unit, range and the reason for the default.
:class:`EstimatorConfig` (a frozen dataclass built from it) is the estimator's one
configuration object; the node parameters and ``ipmc-model estimate`` flags are generated
from the same table (:mod:`~ipmc_sensor_ros.interface.specs`), so names, units and ranges
agree everywhere.  The model the settings parametrise is :mod:`.statespace`;
``docs/estimator.md`` says what each assumes.
"""
from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

from ..errors import ParameterError

__all__ = ['EstimatorConfig', 'SETTINGS', 'Setting', 'CONFIG_FIELDS', 'MAINS_CHOICES',
           'parse_mains']


class Setting(NamedTuple):
    """One setting: name, default, unit, allowed range (inclusive) and meaning + reason."""

    name: str
    default: float
    unit: str
    low: float
    high: float
    text: str


SETTINGS = (
    Setting('motion_rms_m', 1e-3, 'm', 1e-7, 1.0,
            "RMS of the tip's motion about its working point in the prior: the paper's crank "
            'moves the tip +-2 mm; a scale, not a limit'),
    Setting('motion_corner_hz', 10.0, 'Hz', 1e-3, 100.0,
            "corner of the motion's deflection spectrum about its working point: below it the "
            "velocity's power falls as f^2, so a steady current is offset, not motion; an "
            'unknown offset is learned while moving, and the causal estimate loses least to it '
            '(10 Hz, inside the 1-20 Hz band of the paper, measured best on the scenarios)'),
    Setting('motion_bandwidth_hz', 50.0, 'Hz', 0.1, 1e4,
            'largest upper corner of the motion spectrum (third order above it): above the '
            '1-20 Hz band and a 30 Hz free vibration; without a periodic model the data choose '
            'it, a half or a quarter'),
    Setting('periodic_remainder_rms_m', 20e-6, 'm', 1e-9, 1.0,
            "largest RMS of the motion a periodic model leaves (a crank's play, the rig's "
            'vibration): the motion prior once the periodic motion is modelled, small, so an '
            'offset is learned within a few periods; the data choose it, a quarter or a '
            'sixteenth of it by likelihood'),
    Setting('motion_speed_walk', 7e-3, '1/sqrt(s)', 0.0, 1.0,
            "random walk of the periodic motion's relative speed: a DC motor's speed wobbles "
            'by ~1 % over two seconds; a speed has inertia, so each periodic phasor turns '
            "at a rate that walks by motion_rms_m x 2 pi f_motion x this (the phasor's "
            'acceleration, not its velocity, is random)'),
    Setting('motion_harmonics', 3, '', 1, 10,
            "periodic-motion harmonics modelled: a crank-slider's second and third are a "
            'few percent of the first'),
    Setting('motion_fundamentals', 1, '', 1, 5,
            'periodic motions of unrelated fundamentals modelled together, each with its '
            'harmonics, found one after another in what the others leave: a sum of sines on '
            'a shaker, a crank on a vibrating base (up to 3 is worth it there); 1 by default, '
            'since on the drawn records (two sines, then a move to a hold) the stiff model of '
            'two sines lost more where they ended than it gained while they ran'),
    Setting('working_point_walk_m', 1e-6, 'm/sqrt(s)', 0.0, 1.0,
            'random walk of the working point while moving: the stimulus, not drift, moves it; '
            'a rest sets it where the tip is held'),
    Setting('start_level_m', 10e-6, 'm', 1e-9, 1.0,
            'RMS of the working point at the start: a sensor at rest when the estimator '
            'starts is at its rest position'),
    Setting('offset_prior_a', 30e-9, 'A', 1e-15, 1e-3,
            'RMS of the current offset before it is learned: DAQ and amplifier offsets are nA '
            'to tens of nA; while it is unknown a moving estimate loses a few percent of its '
            'amplitude, so the prior is not wider than offsets are'),
    Setting('offset_walk_a', 1e-12, 'A/sqrt(s)', 0.0, 1e-6,
            'random walk of the offset: small, since every offset change assumed while moving '
            'is a deflection ramp the sensor cannot show (H(0) = 0)'),
    Setting('offset_jump_a', 30e-9, 'A', 0.0, 1e-3,
            'RMS of a jump of the offset (an amplifier re-zeroed, a range switched): as wide as '
            'offsets are (offset_prior_a), since a re-zero can leave it anywhere they lie; a '
            'still current the offset does not explain, for a rest window out of a still '
            'stretch or jump_hold_s after a motion, is taken for one; 0: the offset never '
            'jumps'),
    Setting('jump_hold_s', 1.0, 's', 0.0, 60.0,
            'how long a current still at a level the offset does not explain must hold after '
            "a motion to be taken for a jump of the offset: a smooth move's current is flat "
            'within the noise about its peak for up to ~0.6 s (0.3 mm over 10 s at 0.2 nA), a '
            'hold after a move lasts seconds; out of a still stretch (and at 0) a rest window '
            'is enough'),
    Setting('jump_search_s', 10.0, 's', 0.0, 60.0,
            'the longest motion in which a jump of the offset found at the hold after it is '
            "placed by the motion's current (its likely time moves the level the hold starts "
            "from); the motion's samples are kept and filtered again when such a jump is "
            'found, ~0.1 ms a sample on a 2-core machine, a pause the node takes once per '
            'jump (hence at most 60 s); after a longer motion the jump is taken at the hold; '
            '0: always'),
    Setting('offset_drift_a_per_s', 0.05e-9, 'A/s', 0.0, 1e-3,
            "RMS of the offset's drift rate before it is learned: 3 nA a minute, a DAQ "
            'warming up; a short rest cannot tell a larger drift from noise'),
    Setting('offset_drift_walk_a_per_s', 1e-13, 'A/s/sqrt(s)', 0.0, 1e-6,
            "random walk of the offset's drift rate: thermal drift changing over minutes"),
    Setting('line_prior_a', 1e-6, 'A', 1e-15, 1e-3,
            'RMS of each mains-line component before it is learned: hum near mains wiring '
            'reaches a microampere'),
    Setting('line_walk_a', 1e-9, 'A/sqrt(s)', 0.0, 1e-3,
            'random walk of each mains-line component: a hum changing over seconds (a line '
            'frequency error it cannot follow retunes the model)'),
    Setting('line_harmonics', 3, '', 1, 5,
            'mains harmonics modelled: the line, its second and its third'),
    Setting('current_noise_a', 20e-9, 'A', 1e-15, 1e-3,
            'white noise RMS per sample assumed until measured (the filter measures it within '
            'a second)'),
    Setting('sampled_at_stamp_prior', 0.5, '', 0.0, 1.0,
            'prior probability that each stamp is the instant its sample was taken (a DAQ '
            "timed by the host), not a host's time for a sample taken on the DAQ's own clock "
            '(the stamp late by a varying delay): at 0.5 the data decide (the innovations '
            "against what the stamps' offsets from their slots would explain); 0 or 1 fixes it"),
    Setting('noise_average_s', 1.0, 's', 1e-3, 3600.0,
            'averaging time of the measured white-noise variance: long against a sample, '
            'short against a record (the noise is known this long after the start; the '
            "periodic model's test counts the innovations from then)"),
    Setting('nonlinear_mean_corner_hz', 0.005, 'Hz', 1e-6, 10.0,
            "corner of the running mean of a nonlinear sensor's T(w) - w restored while "
            'moving (time constant 32 s): many periods of a 1 Hz crank, while a 0.2 s move '
            'to a hold shifts it by 0.6 % of its gap'),
    Setting('rest_velocity_m_s', 1e-6, 'm/s', 1e-12, 1.0,
            "RMS velocity of a tip at rest (the rest pseudo-measurement's std): a hold creeps "
            'less than 4 um in 4 s'),
    Setting('rest_window_s', 0.2, 's', 1e-3, 60.0,
            'window of the rest test: five periods of the slowest crank of the paper'),
    Setting('false_alarm', 1e-6, '', 1e-15, 0.5,
            "false-alarm level of each of the filter's tests: the rest tests (chi-square on "
            'the window spread and mean and on each sample, the per-sample rate of the '
            'two-sided CUSUM and of the shifted-mean ratio at all ages), a periodic '
            "model's test per stretch and its CUSUM per sample, "
            "and a mains line's frequency step per check"),
)

#: Names of the settings, in order (node parameters and CLI flags use the same names).
CONFIG_FIELDS = tuple(s.name for s in SETTINGS)
_BY_NAME = {s.name: s for s in SETTINGS}


def _check(self) -> None:
    for s in SETTINGS:
        value = getattr(self, s.name)
        integer = isinstance(s.default, int)
        ok = (not isinstance(value, bool) and isinstance(value, (int, float))
              and (not integer or isinstance(value, int)) and math.isfinite(value)
              and s.low <= value <= s.high)
        if not ok:
            what = 'an integer' if integer else 'a number'
            unit = f' {s.unit}' if s.unit else ''
            raise ParameterError(f"parameter '{s.name}' must be {what} in [{s.low:g}, {s.high:g}]"
                                 f'{unit}, got {value!r}')
    if not self.motion_corner_hz < self.motion_bandwidth_hz:
        raise ParameterError(f"parameter 'motion_corner_hz' ({self.motion_corner_hz:g} Hz) must "
                             f"be below 'motion_bandwidth_hz' ({self.motion_bandwidth_hz:g} Hz)")


def _replace(self, **changes):
    """Return a copy with ``changes`` (validated)."""
    unknown = sorted(set(changes) - set(CONFIG_FIELDS))
    if unknown:
        raise ParameterError(f'unknown estimator setting(s) {unknown}; known: '
                             f'{list(CONFIG_FIELDS)}')
    return dataclasses.replace(self, **changes)


def _doc() -> str:
    lines = ['Settings of the Kalman deflection estimator (generated from :data:`SETTINGS`).', '',
             'Attributes', '----------']
    for s in SETTINGS:
        lines += [f'{s.name} : {type(s.default).__name__}',
                  f'    {s.text} [{s.unit or "1"}; default {s.default:g}].']
    return '\n'.join(lines)


EstimatorConfig = dataclasses.make_dataclass(
    'EstimatorConfig', [(s.name, type(s.default), dataclasses.field(default=s.default))
                        for s in SETTINGS],
    frozen=True, namespace={'__post_init__': _check, 'replace': _replace, '__doc__': _doc(),
                            '__module__': __name__})


def setting(name: str) -> Setting:
    """Return the :class:`Setting` called ``name``."""
    return _BY_NAME[name]


def fractions_of(config, name: str, fractions) -> list:
    """Return ``fractions`` of setting ``name`` in ``config``, within its range, largest first."""
    value, low = getattr(config, name), _BY_NAME[name].low
    return sorted({max(f * value, low) for f in fractions}, reverse=True)


#: Values of ``mains_hz``.
MAINS_CHOICES = ('auto', 0, 50, 60)


def parse_mains(value) -> str | float:
    """Return ``'auto'`` or the line frequency 0, 50.0, 60.0 (``mains_hz``)."""
    if isinstance(value, str) and value.strip().lower() == 'auto':
        return 'auto'
    try:
        f = float(value)
    except (TypeError, ValueError):
        f = math.nan
    if f not in (0.0, 50.0, 60.0):
        raise ParameterError(f"parameter 'mains_hz' must be 'auto', 0, 50 or 60, got {value!r}")
    return f


#: Every number written as a module-level literal in ``ipmc_sensor_ros/estimation``, by kind:
#: ``tuning``, a choice of the Kalman estimator's model and filter the data do not make (at
#: most 10; the settings above are the rest); ``stream``, the time base's rules for stamps
#: (:mod:`.timebase`, :mod:`.stream`, both cores); ``physical``; ``numerical``, precision,
#: cost and sizes that do not change an estimate beyond rounding; ``limit``, what input is
#: accepted; ``baseline``, the leaky core, its mains notch and the status's line detector.
#: ``test_docs`` finds every such literal and checks it is here; ``docs/estimator.md`` lists
#: them with their reasons.
CODE_CONSTANTS = {
    'innovations.CUSUM_CHANGE_SIGMAS': 'tuning', 'instants.STAMP_WINDOW': 'tuning',
    'lines.FIND_FALSE_ALARM': 'tuning', 'motion_band.BAND_CHOICES': 'tuning',
    'motionline.MOTION_PERIODS': 'tuning', 'motionline.MOTION_LONGEST_S': 'tuning',
    'statespace.MOTION_WOBBLE': 'tuning', 'statespace.MOTION_WOBBLE_HZ': 'tuning',
    'noise.NOISE_CLIP': 'tuning', 'periodic.REMAINDER_CHOICES': 'tuning',
    'timebase.JITTER_FRACTION': 'stream', 'timebase.RATE_WINDOW_S': 'stream',
    'timebase.FIRST_WINDOW_SAMPLES': 'stream', 'timebase.RELOCK_MIN_SAMPLES': 'stream',
    'timebase.SIGNIFICANCE': 'stream', 'stream.RATE_FOLLOW_FRACTION': 'stream',
    'lines.NOMINAL_LINES_HZ': 'physical', 'lines.SEARCH_HZ': 'physical',
    'limits.DEFLECTION_LIMIT_PER_LENGTH': 'physical',
    'lines.PAD': 'numerical', 'lines._TINY': 'numerical', 'motionline.MOTION_RATE_HZ':
    'numerical', 'motionline._SIDEBANDS': 'numerical', 'motionline._RATES': 'numerical',
    'noise.NOISE_FLOOR_A': 'numerical', 'statespace.HOLD_RELEASE': 'numerical',
    'statespace.OFF_SLOT_STEPS': 'numerical', 'smoother.CHUNK_SAMPLES': 'numerical',
    'inverse.SMALL_BLOCK_SAMPLES': 'numerical',
    'accounting.MAX_BLOCK_SAMPLES': 'limit', 'accounting.MAX_ABS_CURRENT_A': 'limit',
    'fixed_lag.MAX_LAG_SAMPLES': 'limit', 'timebase.MAX_STAMP_S': 'limit',
    'timebase.MAX_WINDOW_SAMPLES': 'limit',
    'leaky_design.DEFAULT_LEAK_CORNER_HZ': 'baseline', 'mains.LINE_WARN_RATIO': 'baseline',
    'mains.DETECT_RATE_HZ': 'baseline',
}
