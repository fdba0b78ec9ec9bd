# SPDX-License-Identifier: Apache-2.0
"""Plugin example: charge leaking through the polymer's bulk resistance."""
from ipmc_sensor_ros.physics.effects import Effect, EffectParameter


class PolymerLeakage(Effect):
    name = 'polymer_leakage'
    summary = ('The electrode capacitance discharges through the ionomer: '
               'the current is high-passed.')
    physics = 'A finite bulk resistance R in parallel with the double-layer capacitance C.'
    equation = 'H -> H s tau / (1 + s tau), tau = R C'
    signature = 'Gain loss and phase lead at low frequency, the same for every sample.'
    reference = "Example plugin of ipmc_sensor_ros (docs/workbench.md, 'Writing an effect')."
    parameters = (EffectParameter('time_constant_s', 's', 0.1, 1e-3, 100.0, (0.005, 10.0),
                                  'leakage time constant tau = R C'),)

    def factor(self, s, model, values):
        tau = values['time_constant_s']
        return s * tau / (1 + s * tau)
