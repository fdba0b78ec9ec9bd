# SPDX-License-Identifier: Apache-2.0
"""
The broad motion prior's upper corner, chosen by the data while no periodic model runs.

``motion_bandwidth_hz`` says how fast the prior's tip may move: above it the motion's
spectrum falls as f^-6 (:mod:`.statespace`).  At its 50 Hz (a 30 Hz free vibration, a
20 Hz crank's harmonics) the prior expects a jerk that a slow motion never has: the
current's one-sample prediction is wide, the filter follows the noise, and the level of a
slow motion wanders (drawn record 5, two slow sines then a hold, 1.06 %; record 57, a slow
1.3 mm move, 6.5 %).  So at each check the stretch since the last one is filtered again
with the upper corner at a half and a quarter of the setting (above ``motion_corner_hz``),
and the likeliest (twice the negative log-likelihood of its innovations, the sums the filter
keeps) takes over from the stretch's start, as a periodic model's remainder is chosen
(:func:`~.periodic.likeliest`); the current's high frequencies, which the sensor passes,
are what tells the corners apart.  A periodic motion is still searched for up to half the
setting (:func:`~.motionline.measure_recent` takes the estimator's settings): searched up
to half the corner chosen, a 7 Hz crank under a 12.5 Hz prior was never modelled (drawn
record 13, 6.5 % instead of 1.1 %).  A stretch spent still is not filtered again: the rest
measurement holds the tip there, so its likelihood hardly differs between corners (and
refiltering it was most of the choice's cost, e.g. 75 -> 320 us a row on a record that
steps and holds).
"""
from __future__ import annotations

from .config import fractions_of
from .periodic import nll_of, refilter
from .statespace import StateSpaceModel

__all__ = ['BAND_CHOICES', 'band_choices_hz', 'likelier_band']

#: The upper corners tried, as fractions of ``motion_bandwidth_hz`` (the largest).
BAND_CHOICES = (1.0, 0.5, 0.25)


def band_choices_hz(config) -> list:
    """Return the upper corners tried, Hz: above the lower corner and within range."""
    return [hz for hz in fractions_of(config, 'motion_bandwidth_hz', BAND_CHOICES)
            if hz > config.motion_corner_hz]


def likelier_band(span, filt, state, config, reduced, build) -> tuple | None:
    """
    Return (filter, its run over ``span``) with a likelier upper corner, or None: keep ``filt``.

    ``span``: the stretch since the last check (:class:`~.periodic.Stretch`), run under
    ``filt`` to ``state``; ``config``: the estimator's settings; ``reduced``: the sensor's
    reduced model; ``build(model)``: the estimator's filter of a model.  Only under the
    broad prior, on a stretch run wholly under ``filt`` that was not spent still.
    """
    model = filt.model
    if model.motion_hz or span.filter is not filt or not span.moved or span.deferred:
        return None
    now = model.config.motion_bandwidth_hz
    lowest = nll_of(span, filt, state)
    best = None
    for hz in band_choices_hz(config):
        if hz == now:
            continue
        other = build(StateSpaceModel(reduced, model.config.replace(motion_bandwidth_hz=hz),
                                      model.sample_rate_hz, model.fundamentals_hz))
        run = refilter(span, other)
        if run.nll < lowest:
            best, lowest = (other, run), run.nll
    return best
