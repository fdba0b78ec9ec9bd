# SPDX-License-Identifier: Apache-2.0
"""
The rest test: whether the sensor is still over the last ``rest_window_s``.

A still sensor's current is its offset, the mains lines and white noise (H(0) = 0: a held
deflection gives no current).  Over the window's N samples of r = i - lines (the lines as
the filter predicts them), two chi-square tests at the level ``rest_false_alarm`` decide:

* **spread**: sum (r - mean r - lines)^2 / R < chi2_{N-1-2K}: no motion current beyond the
  noise R, which the filter measures (:mod:`.filter`), once the window's own least-squares
  fit of the K modelled mains lines is removed (a hum the filter has not learned yet does not
  hide a rest; at rest the filter then learns it within a window);
* **level**: (mean r - b)^2 / (R/N + P_b) < chi2_1: the window's mean agrees with the
  filter's offset b within its own uncertainty P_b (so an offset not yet learned does not
  hide a rest, and a slow deflection ramp, a steady current the spread cannot see, is
  motion).

and every sample of the window must agree with rest on its own: (r_k - b)^2 < chi2_1 (R + P_b)
(a motion that starts ends the rest at its first telling sample, before the pseudo-measurements
below could push its current into the offset; ``RestTest.sample_ok``).

When all pass, the filter applies the zero-velocity pseudo-measurements (as zero-velocity
updates in foot-mounted inertial navigation): the tip velocity and the motion's current are
zero within ``rest_velocity_m_s``.  The test runs on every sample; a window that fails ends
the rest at once.  Motion whose current stays within the noise over a whole window is taken
for rest; its deflection is then below ``R0^-1 sqrt(R/N)`` per second (R0 = R_n(0)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.stats import chi2

__all__ = ['RestTest', 'CUSUM_DRIFT']

#: CUSUM drift, in noise sigmas: half the smallest shift it must see quickly (a motion whose
#: current is one noise sigma; smaller ones are left to the window's level test).
CUSUM_DRIFT = 0.5


@dataclass(frozen=True)
class RestTest:
    """Thresholds of the two tests for a window of ``n`` samples at ``false_alarm``."""

    n: int
    spread_limit: float
    level_limit: float
    cusum_limit: float = math.inf

    def sample_ok(self, r: float, offset_a: float, offset_var_a2: float, noise_var_a2: float,
                  cusum: tuple[float, float]) -> tuple[bool, tuple[float, float]]:
        """
        Test one sample r against a still sensor (offset + noise); return (ok, new CUSUM).

        A sample that fails restarts the CUSUM.
        """
        z = (r - offset_a) / math.sqrt(noise_var_a2 + offset_var_a2)
        up = max(0.0, cusum[0] + z - CUSUM_DRIFT)
        down = max(0.0, cusum[1] - z - CUSUM_DRIFT)
        ok = z * z <= self.level_limit and up <= self.cusum_limit and down <= self.cusum_limit
        return ok, ((up, down) if ok else (0.0, 0.0))

    @classmethod
    def design(cls, window_s: float, sample_rate_hz: float, false_alarm: float,
               lines: int = 0) -> 'RestTest':
        """Thresholds for a window of ``window_s`` with ``lines`` mains lines fitted in it."""
        n = max(8 + 2 * lines, int(round(window_s * sample_rate_hz)))
        # Siegmund: mean run length to a false alarm ~ exp(2 k (h + 1.166)) / (2 k^2) samples,
        # one-sided; two sides halve it
        k = CUSUM_DRIFT
        cusum = math.log(2 * k * k / (2 * false_alarm)) / (2 * k) - 1.166
        return cls(n, float(chi2.isf(false_alarm, n - 1 - 2 * lines)),
                   float(chi2.isf(false_alarm, 1)), max(cusum, 1.0))

    def still(self, total: float, total_sq: float, line_energy: float, offset_a: float,
              offset_var_a2: float, noise_var_a2: float) -> bool:
        """
        Return True if a full window is consistent with a still sensor.

        Parameters
        ----------
        total : float
            Sum of r over the window, A.
        total_sq : float
            Sum of r^2 over the window, A^2.
        line_energy : float
            Energy of the window's least-squares mains lines, A^2.
        offset_a : float
            The filter's offset, A.
        offset_var_a2 : float
            Its variance, A^2.
        noise_var_a2 : float
            The measured white-noise variance per sample, A^2.

        """
        n = self.n
        mean = total / n
        spread = max(total_sq - total * mean - line_energy, 0.0)
        if spread > self.spread_limit * noise_var_a2:
            return False
        d = mean - offset_a
        return d * d <= self.level_limit * (noise_var_a2 / n + offset_var_a2)
