# SPDX-License-Identifier: Apache-2.0
"""
Writes the lab-export samples of this directory (run once; the outputs are committed).

They imitate what real rigs export, each in a different dialect, so the
importer is not fitted to one file: a LabVIEW "Write To Measurement File"
text export, a DAQ TSV in ms/um/nA, a European spreadsheet (';', decimal
comma, German names), a transimpedance-amplifier voltage export and a
current-only field recording.  The signal: 5 Hz tip deflection of 0.8 mm on
a 22 mm slim sample, short-circuit current of ~0.3 uA with a 40 nA DAQ
offset, 2 % noise and 50 Hz hum, sampled at 1 kHz for 1 s.
"""
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
rng = np.random.default_rng(20240312)
t = np.arange(1000) / 1000.0
w = 0.8e-3 * np.sin(2 * np.pi * 5 * t)                      # m
i = (3.0e-7 * np.cos(2 * np.pi * 5 * t + 0.3) + 4.0e-8       # A
     + 6e-9 * rng.standard_normal(t.size) + 5e-9 * np.sin(2 * np.pi * 50 * t))

labview = ['LabVIEW Measurement', 'Writer_Version\t2', 'Reader_Version\t2',
           'Separator\tComma', 'Operator\tjd', 'Date\t2024/03/12', 'Time\t14:02:11.5',
           'Channels\t3', '***End_of_Header***']
rows = [f'{a:.3f},{b * 1e3:.6f},{c * 1e6:.5f}' for a, b, c in zip(t, w, i)]
(HERE / 'labview_slim_5Hz.csv').write_text('\n'.join(labview + ['Time [s],Laser [mm],Current [uA]']
                                                     + rows) + '\n')

rows = [f'{a * 1e3:.1f}\t{b * 1e6:.2f}\t{c * 1e9:.2f}' for a, b, c in zip(t, w, i)]
(HERE / 'daq_slim_5Hz.tsv').write_text(
    '# NI DAQ export\r\n# rig: shaker-2\r\n\r\n' + 't (ms)\tdisplacement_um\tI (nA)\r\n'
    + '\r\n'.join(rows) + '\r\n')

rows = [f'{a:.4f};{b * 1e3:.6f};{c * 1e6:.5f}'.replace('.', ',') for a, b, c in zip(t, w, i)]
(HERE / 'tabelle_slim_5Hz.txt').write_text(
    'Messung;Probe slim\nDatum;12.03.2024\nZeit [s];Laser [mm];Strom [µA]\n'
    + '\n'.join(rows) + '\n', encoding='utf-8')

gain = 1e-6  # A per V: 1 V at the amplifier output per uA
rows = [f'{a:.3f},{b * 1e3:.6f},{c / gain:.5f}' for a, b, c in zip(t, w, i)]
(HERE / 'tia_slim_5Hz.csv').write_text('Time_s,Tip_mm,Current [V]\n' + '\n'.join(rows) + '\n')

rows = [f'{a:.3f},{c * 1e9:.2f}' for a, c in zip(t, i)]
(HERE / 'field_current_only.csv').write_text('field run 7, no laser\nTime [s],Current [nA]\n'
                                             + '\n'.join(rows) + '\n')
