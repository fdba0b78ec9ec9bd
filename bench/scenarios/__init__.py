# SPDX-License-Identifier: Apache-2.0
"""
The scenario library that judges the deflection estimator (issue 27, "The bench").

Records are generated **independently of the package**: nothing here imports
``ipmc_sensor_ros``.  :mod:`.sensor` is the paper's exact H2 (eq. 45) typed in from the paper,
evaluated by FFT with a pre-roll and zero padding; :mod:`.motions` the tip motions;
:mod:`.daq` what a real DAQ does (offset, drift, hum, noise, quantisation, host stamps,
dropped rows) and the :class:`Record`; :mod:`.library` the named scenarios, every random draw
from the seed; :mod:`.drawn` records with every ingredient drawn (``draw(index)``).

    from bench.scenarios import build, names
    record = build('crank-5hz-slim-pct-rest', seed=3)
"""
from .daq import Daq, Record
from .drawn import draw
from .library import build, names, QUICK, Scenario, SCENARIOS
from .sensor import frequency_response, GEOMETRIES, MATERIAL, Sensor, sensor_current

__all__ = ['Daq', 'Record', 'draw', 'Scenario', 'SCENARIOS', 'QUICK', 'build', 'names', 'Sensor',
           'GEOMETRIES', 'MATERIAL', 'frequency_response', 'sensor_current']
