# SPDX-License-Identifier: Apache-2.0
"""
Reading limits and conveniences of the workbench text formats.

Units in column names, streaming in chunks, regular-file check, size/row limits,
natural order, read_records.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.workbench import io, textread
from ipmc_sensor_ros.workbench.io import DataFormatError

HERE = Path(__file__).resolve().parent
UNITS = HERE / 'data' / 'units'
HEAD = ('# format: ipmc-timeseries/1\n# sample: slim\n# length_m: 0.022\n# width_m: 0.007\n'
        '# thickness_m: 0.00036\n')


def _write(tmp_path, name, columns, rows):
    p = tmp_path / name
    p.write_text(HEAD + columns + '\n' + ''.join(r + '\n' for r in rows), encoding='utf-8')
    return p


# --- units in column names -------------------------------------------------------
def test_committed_unit_files_are_converted():
    # the rows of the three files are 0.0,0.0,0.0 / 0.001,1.0e-05,2.0e-08 / ... (k-th row
    # k*0.001, k*1e-5, k*2e-8 in the file's units); one division by 1e3 or 1e6 each:
    # correctly rounded, so equal to the decimal literal within 1 ulp (rtol 1e-15)
    k = np.arange(4)
    ms = io.read_timeseries(UNITS / 'ts_time_ms.csv')
    np.testing.assert_allclose(ms.time_s, k * 1e-6, rtol=1e-15, atol=0)
    assert ms.sample_rate_hz == pytest.approx(1e6)
    mm = io.read_timeseries(UNITS / 'ts_deflection_mm.csv')
    np.testing.assert_allclose(mm.deflection_m, k * 1e-8, rtol=1e-15, atol=0)
    np.testing.assert_allclose(mm.current_a, k * 2e-8, rtol=1e-15, atol=0)
    ua = io.read_any(UNITS / 'ts_current_uA.csv')
    np.testing.assert_allclose(ua.current_a, k * 2e-14, rtol=1e-15, atol=0)


@pytest.mark.parametrize('column, cell, expected', [
    ('deflection_um', '250', 2.5e-4), ('deflection_µm', '250', 2.5e-4),
    ('deflection_nm', '250', 2.5e-7), ('current_nA', '40', 4e-8), ('current_mA', '0.5', 5e-4),
    ('current_UA', '3', 3e-6), ('deflection_m', '0.001', 1e-3)])
def test_column_units_converted(tmp_path, column, cell, expected):
    other = 'current_A' if column.startswith('deflection') else 'deflection_m'
    cols = ['time_s', column, other] if column.startswith('deflection') else \
        ['time_s', other, column]
    k = cols.index(column)
    rows = []
    for t in ('0.0', '0.001'):
        cells = [t, '0', '0']
        cells[k] = cell
        rows.append(','.join(cells))
    ts = io.read_timeseries(_write(tmp_path, 'u.csv', ','.join(cols), rows))
    got = ts.deflection_m if column.startswith('deflection') else ts.current_a
    assert got[1] == pytest.approx(expected, rel=1e-15)


def test_written_file_uses_si_columns(tmp_path):
    ts = io.read_timeseries(UNITS / 'ts_deflection_mm.csv')
    out = tmp_path / 'si.csv'
    io.write_timeseries(out, ts)
    assert 'time_s,deflection_m,current_A\n' in out.read_text()
    assert np.array_equal(io.read_timeseries(out).deflection_m, ts.deflection_m)


def test_time_in_ms_messages_say_ms(tmp_path):
    p = _write(tmp_path, 'ms.csv', 'time_ms,current_A', ['0,1e-8', '2,1e-8', '1,1e-8'])
    with pytest.raises(DataFormatError, match=r'ms\.csv:9: time decreases: 1\.0 ms after 2\.0 ms'):
        io.read_timeseries(p)


def test_unicode_digits_refused_in_header_and_cells(tmp_path):
    p = tmp_path / 'h.csv'
    arabic_indic = '\u0660.\u0660\u0662\u0662'  # 0.022 in Arabic-Indic digits
    p.write_text(HEAD.replace('0.022', arabic_indic) + 'time_s,current_A\n0,0\n1,0\n',
                 encoding='utf-8')
    with pytest.raises(DataFormatError, match=r"h\.csv:3: header key 'length_m' must be a finite"):
        io.read_timeseries(p)
    full = _write(tmp_path, 'c.csv', 'time_s,current_A', ['0,0', '\uff11,0'])  # fullwidth 1
    with pytest.raises(DataFormatError, match=r"c\.csv:8: non-numeric cell '\uff11' in column "
                                              r'time_s'):
        io.read_timeseries(full)


# --- streaming: same answer for every chunk size ------------------------------------
def _outcome(path):
    try:
        ts = io.read_any(path)
    except DataFormatError as exc:
        return str(exc)
    return (ts.time_s.tolist(), None if ts.deflection_m is None else ts.deflection_m.tolist(),
            ts.current_a.tolist())


@pytest.mark.parametrize('case', ['valid', 'bad_cell_late', 'time_back_then_bad_cell',
                                  'blank_inside', 'blank_at_end', 'nan', 'crlf'])
def test_chunking_does_not_change_results(tmp_path, monkeypatch, case):
    rows = [f'{k / 1000!r},{k * 1e-6!r},{(-1) ** k * 3e-8!r}' for k in range(300)]
    if case == 'bad_cell_late':
        rows[250] = '0.25,abc,0'
    if case == 'time_back_then_bad_cell':
        rows[40] = '0.038,0,0'  # time goes back on line 47 of the file, a bad cell later
        rows[200] = '0.2,x,0'
    if case == 'blank_inside':
        rows[120] = '  '
    if case == 'nan':
        rows[299] = '0.299,nan,0'
    p = _write(tmp_path, f'{case}.csv', 'time_s,deflection_m,current_A', rows)
    if case == 'blank_at_end':
        p.write_text(p.read_text() + '\n \n\n')
    if case == 'crlf':
        p.write_bytes(p.read_bytes().replace(b'\n', b'\r\n'))
    reference = _outcome(p)
    for chunk in (7, 64, 1000, 4096):
        monkeypatch.setattr(textread, 'CHUNK_BYTES', chunk)
        assert _outcome(p) == reference, chunk
    if case in ('valid', 'blank_at_end', 'crlf'):
        assert reference[0] == [k / 1000 for k in range(300)]
    else:
        expected = {'bad_cell_late': r"bad_cell_late\.csv:257: non-numeric cell 'abc'",
                    'time_back_then_bad_cell': r'time_back_then_bad_cell\.csv:47: time decreases',
                    'blank_inside': r'blank_inside\.csv:127: blank line between data rows',
                    'nan': r"nan\.csv:306: NaN/Inf cell 'nan'"}[case]
        assert isinstance(reference, str)
        import re
        assert re.search(expected, reference), reference


# --- non-regular files and limits ---------------------------------------------------
def test_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / 'pipe.csv'
    os.mkfifo(fifo)
    code = ('import sys\nfrom ipmc_sensor_ros.workbench.io import read_any, DataFormatError\n'
            'try:\n    read_any(sys.argv[1])\nexcept DataFormatError as e:\n    print(e)\n')
    # a child process with a timeout: a regression would block on open(), not fail
    out = subprocess.run([sys.executable, '-c', code, str(fifo)], capture_output=True, text=True,
                         timeout=60, cwd=HERE.parent, check=True).stdout
    assert 'pipe.csv: not a regular file (a FIFO (named pipe))' in out


def test_device_is_refused():
    with pytest.raises(DataFormatError, match=r'/dev/zero: not a regular file \(a character '
                                              r'device\)'):
        io.read_any('/dev/zero')
    with pytest.raises(DataFormatError, match=r'not a regular file'):
        io.read_records(['/dev/zero'])


def test_row_and_byte_limits(tmp_path):
    p = _write(tmp_path, 'big.csv', 'time_s,current_A', [f'{k},0' for k in range(20)])
    assert io.read_any(p, max_rows=20).n_samples == 20
    with pytest.raises(DataFormatError, match=r'big\.csv:17: more than 10 data rows \(max_rows\)'):
        io.read_any(p, max_rows=10)
    size = p.stat().st_size
    with pytest.raises(DataFormatError, match=rf'big\.csv: file is {size} bytes, above the limit '
                                              r'of 100 bytes \(max_bytes\)'):
        io.read_timeseries(p, max_bytes=100)


def test_very_long_line_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(textread, 'MAX_LINE_BYTES', 1000)
    p = tmp_path / 'long.csv'
    p.write_text('# ' + 'x' * 5000 + '\n')
    with pytest.raises(DataFormatError, match=r'long\.csv:1: line longer than 1000 bytes'):
        io.read_any(p)


def test_failed_write_leaves_nothing(tmp_path):
    t = np.array([0.0, 0.001, 0.001])
    ts = io.TimeSeries('', 'slim', PAPER_SAMPLES['slim'], {}, 1000.0, t, np.zeros(3))
    with pytest.raises(DataFormatError, match=r'refusing to write an invalid time series: '
                                              r'duplicate time'):
        io.write_timeseries(tmp_path / 'dup.csv', ts)
    assert list(tmp_path.iterdir()) == []


# --- natural order and read_records -------------------------------------------------
def test_natural_key_orders_numbers_as_numbers():
    names = ['short_13Hz.csv', 'short_2Hz.csv', 'short_1Hz.csv', 'short_1.5Hz.csv', 'big_1Hz.csv']
    assert sorted(names, key=io.natural_key) == ['big_1Hz.csv', 'short_1Hz.csv', 'short_1.5Hz.csv',
                                                 'short_2Hz.csv', 'short_13Hz.csv']


def _series(deflection=True, n=20):
    t = np.arange(n) / 1000.0
    return io.TimeSeries('', 'slim', PAPER_SAMPLES['slim'], {}, 1000.0, t, 1e-7 * np.sin(t * 50),
                         1e-4 * np.cos(t * 50) if deflection else None)


def test_read_records_sorts_and_skips_current_only(tmp_path):
    d = tmp_path / 'runs'
    d.mkdir()
    for name in ('short_13Hz', 'short_2Hz', 'short_1Hz'):
        io.write_timeseries(d / f'{name}.csv', _series())
    io.write_timeseries(d / 'field_0.csv', _series(deflection=False))
    (d / 'notes.md').write_text('not data\n')
    got = io.read_records([d])
    assert [Path(r.path).name for r in got.records] == ['short_1Hz.csv', 'short_2Hz.csv',
                                                        'short_13Hz.csv']
    assert got.skipped == [(str(d / 'field_0.csv'), 'no deflection column (current only)')]
    # without the need for deflection, nothing is skipped
    assert len(io.read_records(d, need_deflection=False).records) == 4
    # a current-only file named on its own is an error: it was asked for
    with pytest.raises(DataFormatError, match=r'field_0\.csv: no deflection column .*needs '
                                              'measured deflection'):
        io.read_records([d / 'field_0.csv'])
    only = tmp_path / 'only'
    only.mkdir()
    io.write_timeseries(only / 'f.csv', _series(deflection=False))
    with pytest.raises(DataFormatError, match=r'no usable records \(1 skipped'):
        io.read_records([only])
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(DataFormatError, match=r'empty: directory holds no'):
        io.read_records([empty])


def test_read_records_reads_bags_in_a_directory(tmp_path):
    pytest.importorskip('rosbags')
    d = tmp_path / 'mixed'
    d.mkdir()
    io.write_bag(d / 'run_10', _series())
    io.write_bag(d / 'run_9', _series())
    io.write_timeseries(d / 'run_9b.csv', _series())
    got = io.read_records(d)
    assert [Path(r.path).name for r in got.records] == ['run_9', 'run_9b.csv', 'run_10']


def test_committed_frf_unit_files_are_converted():
    # phase 1.48 rad and 1.05 rad -> degrees; 0.6 and 6.3 rad/s -> Hz; 1.0 uA/m -> A/m:
    # one multiplication each (rtol 1e-15)
    rad = io.read_frf(UNITS / 'frf_phase_rad.csv')
    np.testing.assert_allclose(rad.phase_deg, np.degrees([1.48, 1.05]), rtol=1e-15)
    w = io.read_any(UNITS / 'frf_frequency_rad_s.csv')
    np.testing.assert_allclose(w.frequency_hz, np.array([0.6, 6.3]) / (2 * np.pi), rtol=1e-15)
    std = io.read_frf(UNITS / 'frf_gain_std.csv')
    np.testing.assert_allclose(std.gain_std_a_per_m, [1e-6, 1e-6], rtol=1e-15)
    assert std.phase_std_deg.tolist() == [1.0, 1.0]


@pytest.mark.parametrize('column, factor', [('gain_uA_per_mm', 1e-3), ('gain_nA_per_um', 1e-3),
                                            ('gain_mA_per_m', 1e-3), ('gain_A_per_mm', 1e3)])
def test_frf_gain_units(tmp_path, column, factor):
    p = tmp_path / 'g.csv'
    p.write_text(HEAD.replace('ipmc-timeseries/1', 'ipmc-frf/1')
                 + f'frequency_hz,{column},phase_deg\n1,2.0,10\n2,4.0,20\n')
    np.testing.assert_allclose(io.read_frf(p).gain_a_per_m, [2 * factor, 4 * factor], rtol=1e-15)


def test_bag_fifos_refused(tmp_path):
    pytest.importorskip('rosbags')
    fifo = tmp_path / 'run.mcap'
    os.mkfifo(fifo)
    with pytest.raises(DataFormatError, match=r'run\.mcap: run\.mcap is not a regular file'):
        io.read_any(fifo)
    bag = tmp_path / 'bag'
    io.write_bag(bag, _series(), sidecar=False)
    os.mkfifo(tmp_path / 'side.yaml')
    with pytest.raises(DataFormatError, match=r'side\.yaml: sidecar of bag .* is not a regular '
                                              r'file'):
        io.read_bag(bag, sidecar=tmp_path / 'side.yaml')
    os.mkfifo(bag / 'ipmc.yaml')
    with pytest.raises(DataFormatError, match=r'bag: ipmc\.yaml is not a regular file'):
        io.read_bag(bag)


TOKENS = ['1.5e', 'e5', '1e5.5', '--1', '+-1', '1-2', '1 2', '1.2.3', '1e+', '-', '+', '.',
          '1..2', '1e-', '1+', '.e1', '1e999', '1e5', '+.5', '5.', '1E-3', ' 7 ', '1e0001',
          '00012', '-0', '4.9e-324']


@pytest.mark.parametrize('delimiter, decimal', [(',', '.'), (';', ','), ('\t', '.')])
def test_fast_path_accepts_exactly_what_the_line_parser_accepts(delimiter, decimal):
    # the chunk parser (numpy.loadtxt) must never accept a cell the per-line parser
    # refuses, nor read it differently
    for token in TOKENS:
        token = token.replace('.', decimal)
        block = textread._fast_block(f'0{delimiter}{token}\n'.encode(), 2, delimiter, decimal)
        slow = textread.parse_number(token, decimal)
        if block is not None:
            assert slow is not None and block[0, 1] == slow, token
        elif token.strip() in ('1e5', '+.5', '5.', '1E-3', '00012', '-0', '4.9e-324'):
            pytest.fail(f'plain number {token!r} left the fast path')  # speed, not correctness


def test_geometry_header_keys_in_other_units(tmp_path):
    head = HEAD.replace('# length_m: 0.022', '# length_mm: 22').replace(
        '# thickness_m: 0.00036', '# thickness_um: 360')
    p = tmp_path / 'mm.csv'
    p.write_text(head + 'time_s,current_A\n0,0\n0.001,0\n')
    ts = io.read_timeseries(p)
    # converted from the decimal text: exactly the floats 0.022 and 0.00036
    assert (ts.geometry.length_m, ts.geometry.width_m, ts.geometry.thickness_m) == \
        (0.022, 0.007, 0.00036)
    assert ts.extra == {}
    p.write_text(head.replace('# width_m: 0.007', '# width_m: 0.007\n# width_mm: 7')
                 + 'time_s,current_A\n0,0\n0.001,0\n')
    with pytest.raises(DataFormatError, match=r"mm\.csv:5: the width is given twice: 'width_m', "
                                              r"'width_mm'"):
        io.read_timeseries(p)
    p.write_text(head.replace('# length_mm: 22', '# length_mm: 22000')
                 + 'time_s,current_A\n0,0\n0.001,0\n')
    with pytest.raises(DataFormatError, match=r'mm\.csv:3: geometry out of physical range: '
                                              r".*'length_m' = 22\.0 m"):
        io.read_timeseries(p)
