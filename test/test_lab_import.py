# SPDX-License-Identifier: Apache-2.0
"""
Tests of workbench.labimport: lab exports in several dialects into ipmc-timeseries/1.

The samples in test/data/lab/ are written by make_lab.py in five different dialects
(LabVIEW text export, DAQ TSV in ms/um/nA with CRLF, European ';' + decimal comma with
German names, amplifier voltage, current only).  Expected values below are read off the
second data row of each file by hand: 0.001 s, 0.025129 mm (25.13 um), 0.32618 uA.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from ipmc_sensor_ros.physics.parameters import Geometry
from ipmc_sensor_ros.workbench import io
from ipmc_sensor_ros.workbench.labimport import import_lab_file, import_lab_files
from ipmc_sensor_ros.workbench.measurements import DataFormatError

LAB = Path(__file__).resolve().parent / 'data' / 'lab'
META = LAB / 'run.json'
SLIM = Geometry(0.022, 0.007, 0.00036, 'slim')

# row 2 of each file, converted by hand; unit conversions are one division by a power of
# ten, so they equal the decimal literal within float rounding (rtol 1e-12)
CASES = {
    'labview_slim_5Hz.csv': ({}, 2.5129e-5, 3.2618e-7),
    'daq_slim_5Hz.tsv': ({}, 2.513e-5, 3.2618e-7),
    'tabelle_slim_5Hz.txt': ({}, 2.5129e-5, 3.2618e-7),
    'tia_slim_5Hz.csv': ({'current_gain_a_per_v': 1e-6}, 2.5129e-5, 3.2618e-7),
    'field_current_only.csv': ({}, None, 3.2618e-7),
}


@pytest.mark.parametrize('name', sorted(CASES))
def test_each_dialect_is_read_in_si(name):
    options, deflection, current = CASES[name]
    ts = import_lab_file(LAB / name, meta=META, **options)
    assert ts.n_samples == 1000
    assert ts.time_s[1] == pytest.approx(0.001, rel=1e-12)
    assert ts.sample_rate_hz == pytest.approx(1000.0, rel=1e-9)
    assert ts.current_a[1] == pytest.approx(current, rel=1e-12)
    if deflection is None:
        assert ts.deflection_m is None
    else:
        assert ts.deflection_m[1] == pytest.approx(deflection, rel=1e-12)
    assert ts.geometry == SLIM and ts.sample == 'slim'
    assert ts.known == {'temperature_k': 296.0}
    assert ts.extra['meta.operator'] == 'jd'


def test_dialects_agree_with_each_other():
    # the same signal in five dialects: equal up to the digits each file keeps
    # (the TSV keeps 0.01 um = 1e-8 m of deflection, 0.01 nA of current)
    ref = import_lab_file(LAB / 'labview_slim_5Hz.csv', meta=META)
    for name, (options, deflection, _) in CASES.items():
        ts = import_lab_file(LAB / name, meta=META, **options)
        np.testing.assert_allclose(ts.time_s, ref.time_s, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ts.current_a, ref.current_a, rtol=0, atol=1e-11)
        if deflection is not None:
            np.testing.assert_allclose(ts.deflection_m, ref.deflection_m, rtol=0, atol=1e-8)


def test_free_text_header_kept_as_notes():
    ts = import_lab_file(LAB / 'labview_slim_5Hz.csv', geometry='22mm,7mm,360um')
    notes = [v for k, v in sorted(ts.extra.items()) if k.startswith('note_')]
    assert len(notes) == 9
    assert notes[0] == 'LabVIEW Measurement' and notes[-1] == '***End_of_Header***'
    assert notes[4] == 'Operator jd'  # tab collapsed to one space: one-line header value
    assert ts.extra['lab_columns'] == ('time=Time [s], deflection=Laser [mm], '
                                       'current=Current [uA]')
    assert ts.sample == '' and ts.known == {}


def test_geometry_sources_and_conflict(tmp_path):
    by_flag = import_lab_file(LAB / 'daq_slim_5Hz.tsv', geometry='22 mm, 7mm, 0.36mm')
    assert by_flag.geometry == Geometry(0.022, 0.007, 0.00036)
    assert 'geometry_from' not in by_flag.extra             # the user's own, not said back
    by_yaml = import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=LAB / 'run.yaml')
    assert by_yaml.geometry == SLIM
    assert by_yaml.extra['geometry_from'].startswith('run metadata ')
    assert by_yaml.extra['geometry_from'].endswith('run.yaml (length: 22 mm, width: 7 mm, '
                                                   'thickness: 0.36 mm)')
    agree = import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=META, geometry='22mm,7mm,360um')
    assert agree.geometry == SLIM and 'geometry_from' not in agree.extra
    with pytest.raises(DataFormatError, match=r'length conflict: the geometry argument says 11mm '
                                              r'\(0\.011 m\) but run metadata .*run\.json says '
                                              r'length_mm: 22 \(0\.022 m\)'):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=META, geometry='11mm,7mm,360um')
    with pytest.raises(DataFormatError,
                       match=r'no length, width, thickness: give the geometry \(--geometry '):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv')
    with pytest.raises(DataFormatError, match=r"geometry argument: '22' is not a length with a "
                                              r'unit'):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', geometry='22,7,0.36')
    with pytest.raises(DataFormatError, match=r'geometry out of physical range: .*length_m'):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', geometry='22m,7mm,360um')
    with pytest.raises(DataFormatError, match=r"sample conflict: argument says 'big' but run "
                                              r"metadata .* says 'slim'"):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=META, sample='big')
    bad = tmp_path / 'bad.json'
    bad.write_text('{"length_mm": 22, "width_mm": 7, "thickness_um": "thick"}')
    with pytest.raises(DataFormatError, match=r"bad\.json: run metadata thickness_um: 'thick'"):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=bad)
    warm = tmp_path / 'warm.json'
    geometry = '"length_mm": 22, "width_mm": 7, "thickness_um": 360'
    warm.write_text('{' + geometry + ', "temperature_k": "warm"}')
    with pytest.raises(DataFormatError, match=r"warm\.json: run metadata temperature_k: 'warm' "
                                              r'must be a number'):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=warm)
    cold = tmp_path / 'cold.json'
    cold.write_text('{' + geometry + ', "temperature_k": -3}')
    with pytest.raises(DataFormatError, match=r'cold\.json: implausible known value: '
                                              r'.*temperature'):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=cold)
    broken = tmp_path / 'broken.json'
    broken.write_text('{"length_mm": 22,')
    with pytest.raises(DataFormatError, match=r'broken\.json.*not valid JSON'):
        import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=broken)


def test_voltage_needs_a_gain_and_a_current_refuses_one():
    with pytest.raises(DataFormatError, match=r"tia_slim_5Hz\.csv:1: column 'Current \[V\]' is a "
                                              r'voltage: give the transimpedance of the current '
                                              r'amplifier \(--current-gain V_PER_A; '
                                              r'current_gain_a_per_v'):
        import_lab_file(LAB / 'tia_slim_5Hz.csv', meta=META)
    with pytest.raises(DataFormatError, match=r'current_gain_a_per_v = 1e-06 given but column '
                                              r"'Current \[uA\]' is already a current"):
        import_lab_file(LAB / 'labview_slim_5Hz.csv', meta=META, current_gain_a_per_v=1e-6)
    with pytest.raises(DataFormatError, match=r'current_gain_a_per_v must be a finite number > 0'):
        import_lab_file(LAB / 'tia_slim_5Hz.csv', meta=META, current_gain_a_per_v=-1.0)


def _lab(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, encoding='utf-8')
    return p


def test_columns_found_overridden_and_refused(tmp_path):
    two = _lab(tmp_path, 'two.csv', 'Time [s],Laser [mm],Tip (mm),I [nA],Force [N]\n'
                                    '0,1,2,3,9\n0.5,1,2,3,9\n')
    with pytest.raises(DataFormatError, match=r'two\.csv:1: two columns could be the '
                                              r"deflection: \['Laser \[mm\]', 'Tip \(mm\)'\]"):
        import_lab_file(two, geometry='22mm,7mm,360um')
    ts = import_lab_file(two, geometry='22mm,7mm,360um', columns={'deflection': 'Tip (mm)'})
    assert ts.deflection_m.tolist() == [0.002, 0.002]
    assert ts.current_a.tolist() == pytest.approx([3e-9, 3e-9], rel=1e-15)
    bare = _lab(tmp_path, 'bare.csv', 't,current_uA\n0,1\n2,1\n')
    with pytest.raises(DataFormatError, match=r"bare\.csv:1: column 't' \(time\) has no unit"):
        import_lab_file(bare, geometry='22mm,7mm,360um')
    # an explicit name may add the missing unit
    ts = import_lab_file(bare, geometry='22mm,7mm,360um', columns={'time': 't [ms]'})
    assert ts.time_s.tolist() == [0.0, 0.002] and ts.current_a.tolist() == [1e-6, 1e-6]
    with pytest.raises(DataFormatError, match=r"columns: time='Zeit' is not a column"):
        import_lab_file(bare, geometry='22mm,7mm,360um', columns={'time': 'Zeit'})


def test_a_units_row_under_the_names_gives_the_units(tmp_path):
    """Spreadsheet exports: names, then units in a row of their own, then numbers."""
    src = _lab(tmp_path, 'units.csv', 'run 7\nTime,Laser,Current\ns,mm,uA\n0,1,2\n0.5,1,2\n')
    ts = import_lab_file(src, geometry='22mm,7mm,360um')
    assert ts.deflection_m.tolist() == [0.001, 0.001]
    assert ts.current_a.tolist() == pytest.approx([2e-6, 2e-6], rel=1e-15)
    assert ts.extra['lab_columns'] == 'time=Time [s], deflection=Laser [mm], current=Current [uA]'
    # a row under the names that is not all units stays the header
    words = _lab(tmp_path, 'words.csv', 'Time,Laser,Current\nt [s],w [mm],tag\n0,1,2\n1,1,2\n')
    with pytest.raises(DataFormatError, match=r'words\.csv:2: no current column'):
        import_lab_file(words, geometry='22mm,7mm,360um')


def test_a_delimiter_ending_every_line_is_read(tmp_path):
    """Excel writes 'a,b,c,' on every line: an empty last column, not a missing table."""
    src = _lab(tmp_path, 'excel.csv', 'Time [s],Laser [mm],Current [uA],\n0,1,2,\n0.5,1,2,\n')
    ts = import_lab_file(src, geometry='22mm,7mm,360um')
    assert ts.time_s.tolist() == [0.0, 0.5] and ts.deflection_m.tolist() == [0.001, 0.001]
    assert 'unused_columns' not in ts.extra


REFUSED = {  # file text -> the message it must give (file:line where a line applies)
    'wrong.csv': ('Time [s],Deflection [A],Current [A]\n0,1,2\n1,1,2\n',
                  r"wrong\.csv:1: column 'Deflection \[A\]' \(deflection\): unit 'A' is not a "
                  r'unit of deflection'),
    'nocur.csv': ('Time [s],Laser [mm]\n0,1\n1,1\n', r'nocur\.csv:1: no current column among'),
    'back.txt': ('run 3\nTime [ms];Current [µA]\n0;1,5\n2;1,5\n1;1,5\n',
                 r'back\.txt:5: time decreases: 1\.0 ms after 2\.0 ms on line 4; Time \[ms\] must '
                 r'not go back \(a repeated time is left out, counted; one going back is a '
                 r'second run'),
    'cell.csv': ('Time [s],Current [A]\n0,1\n1,x\n',
                 r"cell\.csv:3: non-numeric cell 'x' in column Current \[A\]"),
    'notable.csv': ('just words\nand more words\n', r'notable\.csv:2: no table found in the file'),
    'nan.csv': ('Time [s],Current [A]\n0,1\n1,NaN\n', r"nan\.csv:3: NaN/Inf cell 'NaN'"),
    'dup.csv': ('Time [s],Current [A]\n0,1\n0,1\n0,2\n',
                r'dup\.csv:3: only 1 data row with a time of its own'),
}


@pytest.mark.parametrize('name', sorted(REFUSED))
def test_refused_files_name_file_and_line(tmp_path, name):
    text, message = REFUSED[name]
    with pytest.raises(DataFormatError, match=message):
        import_lab_file(_lab(tmp_path, name, text), geometry='22mm,7mm,360um')


def test_fifo_refused(tmp_path):
    fifo = tmp_path / 'daq.csv'
    os.mkfifo(fifo)
    with pytest.raises(DataFormatError, match=r'daq\.csv: not a regular file'):
        import_lab_file(fifo, geometry='22mm,7mm,360um')


def test_import_lab_files_writes_readable_timeseries(tmp_path):
    out = tmp_path / 'imported'
    names = ['labview_slim_5Hz.csv', 'daq_slim_5Hz.tsv', 'field_current_only.csv']
    written = import_lab_files([LAB / n for n in names], out, meta=META)
    assert written == [out / 'labview_slim_5Hz.csv', out / 'daq_slim_5Hz.csv',
                       out / 'field_current_only.csv']
    for name, path in zip(names, written):
        direct = import_lab_file(LAB / name, meta=META)
        back = io.read_timeseries(path)
        assert np.array_equal(back.time_s, direct.time_s)
        assert np.array_equal(back.current_a, direct.current_a)
        assert back.geometry == direct.geometry and back.extra == direct.extra
        assert (back.deflection_m is None) == (direct.deflection_m is None)
    with pytest.raises(DataFormatError, match=r'labview_slim_5Hz\.csv: output exists'):
        import_lab_files([LAB / names[0]], out, meta=META)
    assert import_lab_files([LAB / names[0]], out, meta=META, overwrite=True) == written[:1]
    # read_records over the imported directory skips the current-only record
    got = io.read_records(out)
    assert len(got.records) == 2 and got.skipped[0][0].endswith('field_current_only.csv')
    # one failing file: nothing written
    fresh = tmp_path / 'fresh'
    with pytest.raises(DataFormatError, match=r"tia_slim_5Hz\.csv:1: column 'Current \[V\]'"):
        import_lab_files([LAB / names[0], LAB / 'tia_slim_5Hz.csv'], fresh, meta=META)
    assert not fresh.exists()


def test_parse_columns_spec():
    from ipmc_sensor_ros.workbench.labimport import parse_columns_spec

    assert parse_columns_spec('time=Time [s], deflection=Tip (mm),current=I_nA') == {
        'time': 'Time [s]', 'deflection': 'Tip (mm)', 'current': 'I_nA'}
    for bad, message in (('time', 'not role=column'), ('time=', 'not role=column'),
                         ('speed=v', "unknown role 'speed'"), ('time=a,time=b', 'twice')):
        with pytest.raises(ValueError, match=message):
            parse_columns_spec(bad)


def _windows_export(path: Path, header: str, columns: str) -> None:
    """Write a German lab PC's export: cp1252, ';' cells, decimal comma, 2 Hz crank, 10 s."""
    t = np.arange(0, 10, 0.002)
    rows = [f'{a:.1f};{b:.5f};{c:.4f}'.replace('.', ',') for a, b, c in
            zip(t * 1e3, np.sin(2 * np.pi * 2 * t), 300 * np.cos(2 * np.pi * 2 * t))]
    path.write_bytes((header + columns + '\n' + '\n'.join(rows) + '\n').encode('cp1252'))


def test_header_geometry_legacy_encoding_and_unused_columns_are_read_and_said(tmp_path):
    """
    Real lab exports: geometry in the free-text header, cp1252 text, German column names.

    Before: 'not UTF-8 text' refused the file; with it re-encoded, the header geometry was
    ignored (no geometry: refused) and 'Auslenkung [mm]' was silently dropped (current-only).
    """
    src = tmp_path / 'messung.txt'
    _windows_export(src, 'Messung vom 20.11.2026\nLänge: 22 mm; Breite: 7 mm; Dicke: 360 µm\n\n',
                    'Zeit [ms];Auslenkung [mm];Strom [nA]')
    ts = import_lab_file(src)
    assert (ts.geometry.length_m, ts.geometry.width_m, ts.geometry.thickness_m) == \
        pytest.approx((0.022, 0.007, 360e-6), rel=1e-12)
    assert ts.extra['text_encoding'] == 'cp1252'
    assert ts.deflection_m is not None      # 'Auslenkung' is the deflection; its peak lies
    assert np.max(ts.deflection_m) == pytest.approx(1e-3, 1e-3)    # between samples
    assert np.max(ts.current_a) == pytest.approx(300e-9, rel=1e-6)  # cos peaks at t = 0
    said = []
    import_lab_files([src], tmp_path / 'out', notice=said.append)
    assert any('read as cp1252' in s for s in said)
    assert any(s.endswith('messung.txt: geometry from the file header (line 2)') for s in said)
    head = (tmp_path / 'out' / 'messung.csv').read_text(encoding='utf-8').splitlines()
    assert sum('Breite' in line for line in head) == 1      # the note; not again beside it
    # English names, one per line, unit in brackets or after a decimal-comma value
    other = tmp_path / 'run.txt'
    _windows_export(other, 'Length [mm]: 22\nwidth = 7 mm\nThickness: 0,36 mm\n',
                    'Time [ms];Laser [mm];Current [nA]')
    assert import_lab_file(other).geometry.thickness_m == pytest.approx(360e-6, rel=1e-12)
    # a header that disagrees with --geometry is refused naming both, never chosen between
    with pytest.raises(DataFormatError, match=r'length conflict: the geometry argument says '
                                              r'.*but the file header says line 2: Länge'):
        import_lab_file(src, geometry='20mm,7mm,360um')


def test_unused_column_and_voltage_current_with_a_gain(tmp_path):
    t = np.arange(0, 4, 0.001)
    src = tmp_path / 'tia.csv'
    rows = '\n'.join(f'{a:.4f},{np.sin(2 * np.pi * 2 * a):.5f},{0.3 * np.cos(a):.6f},21.5'
                     for a in t)
    src.write_text('Time (s),Tip displacement (mm),Amplifier output (V),Temp (C)\n' + rows + '\n')
    ts = import_lab_file(src, geometry='22mm,7mm,360um', current_gain_a_per_v=1e-6)
    assert np.max(ts.current_a) == pytest.approx(0.3e-6, rel=1e-4)
    assert ts.extra['unused_columns'] == 'Temp (C)'
    said = []
    import_lab_files([src], tmp_path / 'out', notice=said.append, geometry='22mm,7mm,360um',
                     current_gain_a_per_v=1e-6)
    assert any('column(s) not imported: Temp (C)' in s for s in said)
    with pytest.raises(DataFormatError, match='no current column'):
        import_lab_file(src, geometry='22mm,7mm,360um')      # a voltage without a gain


def test_a_current_column_in_microvolts_asks_for_the_amplifier_gain(tmp_path):
    """A transimpedance output logged in uV is a voltage, not an unknown unit."""
    src = tmp_path / 'tia_uv.csv'
    src.write_text('Time (s),Current [uV]\n' + '\n'.join(
        f'{k * 1e-3:.3f},{np.sin(k / 50):.5f}' for k in range(2000)) + '\n')
    with pytest.raises(DataFormatError, match=r"column 'Current \[uV\]' is a voltage: give the "
                                              r'transimpedance'):
        import_lab_file(src, geometry='22mm,7mm,360um')
    ts = import_lab_file(src, geometry='22mm,7mm,360um', current_gain_a_per_v=1e-6)
    assert np.max(ts.current_a) == pytest.approx(1e-12, rel=1e-3)    # 1 uV at 1 uA/V


def test_a_repeated_stamp_is_not_imported_and_is_said(tmp_path):
    """
    A host that stamped twice in one tick: the row after is left out, counted and placed.

    As the estimator node refuses a duplicated stamp (one sample, no reset); the output's
    header keeps the count under the node's counter name, and a decrease is still an error.
    """
    text = 'run 9\nTime [ms],Current [nA]\n0,1\n1,2\n1,3\n2,4\n3,5\n3,6\n3,7\n4,8\n'
    src = _lab(tmp_path, 'host.csv', text)
    ts = import_lab_file(src, geometry='22mm,7mm,360um')
    assert ts.time_s.tolist() == [0.0, 0.001, 0.002, 0.003, 0.004]
    assert ts.current_a.tolist() == pytest.approx([1e-9, 2e-9, 4e-9, 5e-9, 8e-9], rel=1e-12)
    assert ts.extra['rejected_duplicate_stamp'] == '3 (lines 5, 8, 9)'
    said = []
    out = import_lab_files([src], tmp_path / 'out', notice=said.append,
                           geometry='22mm,7mm,360um')
    assert any('not imported: 3 (lines 5, 8, 9)' in s for s in said)
    assert '# rejected_duplicate_stamp: 3 (lines 5, 8, 9)' in out[0].read_text().splitlines()
    assert io.read_timeseries(out[0]).time_s.size == 5


def test_a_run_metadata_key_near_a_known_one_is_refused(tmp_path):
    """'temperatur_k' would be a note and the temperature silently unused: refused, named."""
    geometry = '"width_mm": 7, "thickness_um": 360'
    for text, key, near in (('{"length_mm": 22, ' + geometry + ', "temperatur_k": 295}',
                             'temperatur_k', 'temperature_k'),
                            ('{"lenght_mm": 22, ' + geometry + '}', 'lenght_mm', 'length_mm'),
                            ('{"length_mm": 22, ' + geometry + ', "Temperature_K": 296}',
                             'Temperature_K', 'temperature_k'),
                            ('{"geometry": {"lenght_mm": 22, ' + geometry + '}}', 'lenght_mm',
                             'length_mm')):
        meta = tmp_path / 'meta.json'
        meta.write_text(text)
        with pytest.raises(DataFormatError, match=rf"meta\.json: run metadata key '{key}' is "
                                                  rf"not one it reads; did you mean '{near}'"):
            import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=meta)
    meta.write_text('{"length_mm": 22, ' + geometry + ', "operator": "jd"}')
    assert import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=meta).extra['meta.operator'] == 'jd'


def test_a_run_metadata_key_no_header_can_hold_is_named_not_dropped(tmp_path):
    """YAML reads '1: x' as an integer key; 'Operator Name' has a space: named, not kept."""
    meta = tmp_path / 'meta.yaml'
    meta.write_text('length_mm: 22\nwidth_mm: 7\nthickness_um: 360\n1: x\nOperator Name: jd\n')
    ts = import_lab_file(LAB / 'daq_slim_5Hz.tsv', meta=meta)
    assert ts.geometry.length_m == 0.022 and not any(k.startswith('meta.') for k in ts.extra)
    assert ts.extra['meta_keys_left_out'] == '1, Operator Name'
    said = []
    import_lab_files([LAB / 'daq_slim_5Hz.tsv'], tmp_path / 'out', meta=meta,
                     notice=said.append)
    assert any('not kept as notes' in s and '1, Operator Name' in s for s in said)


def test_values_in_a_unit_are_written_as_the_decimals_the_file_gave(tmp_path):
    """
    0.1257 nA is written 1.257e-10, not 1.2570000000000002e-10 (0.1257 / 1e9 in binary).

    One value in four of a 3-decimal column lands an ulp off when divided; each is the double
    nearest its decimal in SI, so the written CSV reads as the file did.
    """
    rows = ''.join(f'{k * 0.5},{v}\n' for k, v in enumerate(
        ('0.1257', '-2.678', '3.202', '0.003', '125.7', '-0.0001')))
    src = _lab(tmp_path, 'nA.csv', 'Time [ms],Current [nA]\n' + rows)
    out = import_lab_files([src], tmp_path / 'out', geometry='22mm,7mm,360um')
    text = out[0].read_text()
    for want in ('1.257e-10', '-2.678e-09', '3.202e-09', '3e-12', '1.257e-07', '-1e-13',
                 '0.0005'):
        assert f',{want}\n' in text or f'\n{want},' in text, want
    assert '00000000' not in text and '99999999' not in text     # no binary noise anywhere


def test_a_current_held_at_its_rail_is_said(tmp_path):
    """
    A transimpedance amplifier at its +-10 V rail: the rows there are said, not silently fitted.

    A trial's 1e6 V/A amplifier clipped 49-72 % of its rows, and diagnose then 'found' a beam
    resonance.  A clean sine near full scale holds its extreme codes far less than 1 %.
    """
    t = np.arange(0, 2, 0.0005)
    for amplitude in (25.0, 9.9):
        volts = np.round(np.clip(amplitude * np.sin(2 * np.pi * 13 * t), -10, 10), 4)
        src = _lab(tmp_path, f'rail_{amplitude:g}.csv', 'Time [s],Current [V]\n' + ''.join(
            f'{a:.4f},{v}\n' for a, v in zip(t, volts)))
        ts = import_lab_file(src, geometry='22mm,7mm,360um', current_gain_a_per_v=1e-6)
        if amplitude > 10:
            held = int(np.count_nonzero(np.abs(volts) == 10))
            assert ts.extra['current_at_limit'] == \
                f'Current [V]: {held} of {t.size} rows at 10 or -10'
        else:
            assert 'current_at_limit' not in ts.extra
