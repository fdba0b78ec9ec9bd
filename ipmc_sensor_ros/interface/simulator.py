# SPDX-License-Identifier: Apache-2.0
"""
The simulator node's parameters and stimulus building.

Without ROS (the node is :mod:`ipmc_sensor_ros.nodes.simulator_node`).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from ..physics.beam import FIDELITIES
from ..simulation.stimuli import STIMULUS_KINDS, Sampled, Stimulus, make_stimulus
from .specs import (DIAGNOSTICS_SPECS, GEOMETRY_SPECS, MATERIAL_SPECS, MODEL_SPECS, QOS_SPECS,
                    Spec, check_choice)

__all__ = ['SIMULATOR_SPECS', 'SIMULATOR_OWN_SPECS', 'CHAIN_PARAMETERS', 'STIMULI',
           'load_stimulus_csv', 'read_stimulus_csv', 'build_stimulus', 'describe_stimulus']

STIMULI = tuple(sorted(STIMULUS_KINDS)) + ('file',)

SIMULATOR_OWN_SPECS = (
    Spec('fidelity', 'model', str, "sensor physics: 'model' (the closed-form model with every "
         "effect, as an order-8 reduction) or 'field' (independent solution of the field "
         'equations; base model and hydration_drift only; ~50x real time)', read_only=True,
         choices=FIDELITIES),
    Spec('beam_model', 'linear', str, "fidelity 'field' only: stress profile from the tip "
         "deflection, 'linear' (the paper's small-deflection beam, eq. 21) or 'elastica' "
         "(large deflection: the physical source of the 'nonlinearity' effect)", read_only=True,
         choices=('linear', 'elastica')),
    Spec('stimulus', 'crank_slider', str, 'tip-deflection stimulus: crank_slider, sweep, '
         'free_vibration, step, robot_motion (holds, moves and slow sines drawn from seed) or '
         'file', choices=STIMULI),
    Spec('motor_frequency_hz', 1.0, float, 'crank_slider: motor (drive) frequency, Hz',
         low=1e-3, high=1e3),
    Spec('crank_radius_m', 0.002, float, 'crank_slider: crank radius r (half the '
         'peak-to-peak deflection), m', low=1e-6, high=1.0),
    Spec('rod_length_m', 0.02, float, 'crank_slider: connecting-rod length l (> r), m',
         low=1e-6, high=10.0),
    Spec('sweep_start_hz', 0.5, float, 'sweep: start frequency, Hz', low=1e-3, high=1e4),
    Spec('sweep_stop_hz', 50.0, float, 'sweep: stop frequency, Hz', low=1e-3, high=1e4),
    Spec('sweep_duration_s', 20.0, float, 'sweep: duration of one sweep (then repeated), s',
         low=1e-3, high=1e6),
    Spec('amplitude_m', 0.001, float, 'sweep, step, free_vibration and robot_motion (levels '
         'within +-amplitude): tip amplitude, m',
         low=-1.0, high=1.0),
    Spec('natural_frequency_hz', 30.0, float, 'free_vibration: natural frequency, Hz',
         low=1e-3, high=1e4),
    Spec('damping_ratio', 0.05, float, 'free_vibration: damping ratio (dimensionless, < 1)',
         low=0.0, high=0.999999),
    Spec('step_start_s', 0.5, float, 'step: time of the step after the start, s',
         low=0.0, high=1e6),
    Spec('stimulus_file', '', str, "file: CSV with columns time_s,deflection_m ('#' comment "
         'lines and one header line allowed), interpolated by a cubic spline'),
    Spec('sample_rate_hz', 1000.0, float, 'DAQ sample rate, Hz', low=1.0, high=1e6),
    Spec('block_size', 10, int, 'samples per published message', low=1, high=100000),
    Spec('realtime_factor', 1.0, float, 'simulated seconds per node-clock second; 0 = fast '
         'mode (one block per 1 ms tick)', low=0.0, high=1e6),
    Spec('duration_s', 0.0, float, 'simulated duration, s (0 = forever); then it logs '
         "'done' and stops publishing", low=0.0, high=1e9),
    Spec('current_gain', 1.0, float, 'measurement chain: amplifier gain error '
         '(dimensionless, 1 = ideal)', low=-1e6, high=1e6),
    Spec('current_offset_a', 0.0, float, 'measurement chain: constant current offset, A',
         low=-1.0, high=1.0),
    Spec('current_offset_drift_a_per_s', 0.0, float, 'measurement chain: drift of the '
         'current offset with simulated time (an amplifier warming up), A/s',
         low=-1e-3, high=1e-3),
    Spec('noise_rms_a', 0.0, float, 'measurement chain: white Gaussian noise RMS, A',
         low=0.0, high=1.0),
    Spec('mains_hz', 0, int, 'measurement chain: mains hum at this line frequency and its '
         'harmonics 2-4: 0 (none), 50 or 60 Hz', low=0, high=60, choices=(0, 50, 60)),
    Spec('mains_rms_a', 0.0, float, 'measurement chain: RMS of the mains hum (line and '
         'harmonics together), A', low=0.0, high=1.0),
    Spec('seed', 0, int, "seed of the noise generator and of robot_motion's moves",
         low=0, high=2 ** 31 - 1),
    Spec('channels', 1, int, "sensors in the array: 'current' and 'deflection_truth' blocks "
         "carry one column per channel ('time_s,current_ch0_A,...' when > 1); each channel is "
         'its own sensor with its own noise (seed + channel)', low=1, high=256),
    Spec('channel_time_offset_s', 0.0, float, 'channel c sees the stimulus at t + c x this '
         'offset (a wave travelling along the array), s', low=-1e3, high=1e3),
    Spec('wait_for_subscribers', 0, int, "start only when 'current' and 'deflection_truth' "
         'each have at least this many matched subscriptions (0 = start at once)',
         low=0, high=1000),
)

#: The simulator parameters that set its measurement chain (keywords of MeasurementChain).
CHAIN_PARAMETERS = ('current_gain', 'current_offset_a', 'current_offset_drift_a_per_s',
                    'noise_rms_a', 'mains_hz', 'mains_rms_a')

SIMULATOR_SPECS = tuple(dataclasses.replace(s, read_only=True) for s in
                        GEOMETRY_SPECS + MATERIAL_SPECS + MODEL_SPECS + SIMULATOR_OWN_SPECS
                        + QOS_SPECS) + DIAGNOSTICS_SPECS


def read_stimulus_csv(path: str | Path) -> np.ndarray:
    """(n, 2) array of (time_s, deflection_m) rows from a CSV file (s, m)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ParameterError(f"parameter 'stimulus_file': cannot read {str(path)!r}: "
                             f'{exc.strerror}') from None
    rows = []
    for number, line in enumerate(lines, 1):
        text = line.split('#', 1)[0].strip()
        if not text:
            continue
        cells = [c.strip() for c in text.split(',')]
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if not rows and cells[:2] == ['time_s', 'deflection_m']:
                continue  # header line
            raise ParameterError(f"parameter 'stimulus_file': {path}:{number}: not two numbers: "
                                 f'{line!r}') from None
        if len(values) != 2:
            raise ParameterError(f"parameter 'stimulus_file': {path}:{number}: expected 2 "
                                 f'columns (time_s, deflection_m), got {len(values)}')
        rows.append(values)
    return np.array(rows, dtype=float).reshape(-1, 2)


def load_stimulus_csv(path: str | Path) -> Sampled:
    """Return a :class:`Sampled` stimulus from a ``time_s,deflection_m`` CSV file (s, m)."""
    data = read_stimulus_csv(path)
    try:
        return Sampled(data[:, 0], data[:, 1])
    except ParameterError as exc:
        raise ParameterError(f"parameter 'stimulus_file': {path}: {exc}") from None


def build_stimulus(values: dict) -> tuple[Stimulus, float]:
    """(stimulus, time offset in stimulus time of sample 0, s) from parameter values."""
    kind = check_choice('stimulus', values['stimulus'], STIMULI)
    if kind == 'file':
        if not values['stimulus_file']:
            raise ParameterError("parameter 'stimulus_file' must name a CSV file when "
                                 "stimulus is 'file'")
        stim = load_stimulus_csv(values['stimulus_file'])
        return stim, stim.start_s
    if kind == 'crank_slider':
        kw = {k: values[k] for k in ('motor_frequency_hz', 'crank_radius_m', 'rod_length_m')}
    elif kind == 'sweep':
        kw = {'amplitude_m': values['amplitude_m'], 'start_frequency_hz': values['sweep_start_hz'],
              'stop_frequency_hz': values['sweep_stop_hz'],
              'duration_s': values['sweep_duration_s']}
    elif kind == 'free_vibration':
        kw = {k: values[k] for k in ('amplitude_m', 'natural_frequency_hz', 'damping_ratio')}
    elif kind == 'robot_motion':
        kw = {'amplitude_m': values['amplitude_m'], 'seed': values['seed']}
    else:  # step
        kw = {'amplitude_m': values['amplitude_m'], 'start_s': values['step_start_s']}
    return make_stimulus(kind, **kw), 0.0


def describe_stimulus(stimulus: Stimulus, values: dict) -> str:
    """Short text of the stimulus and its parameters for the log."""
    if dataclasses.is_dataclass(stimulus):
        args = ', '.join(f'{f.name}={getattr(stimulus, f.name):g}'
                         for f in dataclasses.fields(stimulus))
        return f"{values['stimulus']}({args})"
    return f"{values['stimulus']}({values['stimulus_file']})"
