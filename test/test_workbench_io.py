# SPDX-License-Identifier: Apache-2.0
"""Tests of ipmc_sensor_ros.workbench.io: formats, round trips, bags, malformed corpus."""
from __future__ import annotations

import importlib.util
import math
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ipmc_sensor_ros.physics.parameters import Geometry, PAPER_SAMPLES
from ipmc_sensor_ros.workbench import io
from ipmc_sensor_ros.workbench.io import DataFormatError

HERE = Path(__file__).resolve().parent
CORPUS = HERE / 'data' / 'malformed'
EXPECTED = yaml.safe_load((CORPUS / 'EXPECTED.yaml').read_text())
NOT_CASES = {'EXPECTED.yaml', 'make_bags.py', '__pycache__'}

VALID_TS = """\
# format: ipmc-timeseries/1
# sample: slim
# length_m: 0.022
# width_m: 0.007
# thickness_m: 0.00036
#
# sample_rate_hz: 1000
# temperature_k: 298.15
# youngs_modulus_pa: 5.71e8
# surface_resistance_ohm: 6.05
# operator: jd
# rig.id: shaker-2
time_s,deflection_m,current_A
0.0,0.0,0.0
0.001,1.0e-05,2.0e-08
0.002,2.0e-05,-4.0e-08
0.003,3.0e-05,6.0e-08
"""


def _make_bags_module():
    spec = importlib.util.spec_from_file_location('make_bags', CORPUS / 'make_bags.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope='session')
def make_bags():
    pytest.importorskip('rosbags')
    return _make_bags_module()


@pytest.fixture(scope='session')
def generated(tmp_path_factory, make_bags):
    return make_bags.make_all(tmp_path_factory.mktemp('malformed'))


def _series(n=250, rate=1000.0, deflection=True, t0=0.0, **kw):
    t = t0 + np.arange(n) / rate
    return io.TimeSeries(path='', sample=kw.pop('sample', 'slim'),
                         geometry=kw.pop('geometry', PAPER_SAMPLES['slim']),
                         known=kw.pop('known', {}), sample_rate_hz=rate, time_s=t,
                         current_a=3e-7 * np.sin(2 * np.pi * 7 * t) + 1e-9 * np.cos(t),
                         deflection_m=(1e-3 * np.cos(2 * np.pi * 7 * t)) if deflection else None,
                         extra=kw.pop('extra', {}))


def _assert_same_ts(a: io.TimeSeries, b: io.TimeSeries, *, rate_exact=True):
    assert a.sample == b.sample
    assert a.geometry == b.geometry
    assert a.known == b.known
    assert a.extra == b.extra
    if rate_exact:
        assert a.sample_rate_hz == b.sample_rate_hz
    else:
        assert a.sample_rate_hz == pytest.approx(b.sample_rate_hz, rel=1e-9)
    assert np.array_equal(a.time_s, b.time_s)
    assert np.array_equal(a.current_a, b.current_a)
    if a.deflection_m is None:
        assert b.deflection_m is None
    else:
        assert np.array_equal(a.deflection_m, b.deflection_m)


# ---------------------------------------------------------------------------
# Malformed corpus
# ---------------------------------------------------------------------------
def test_corpus_is_complete_and_large_enough():
    committed = {p.name for p in CORPUS.iterdir()} - NOT_CASES
    missing = committed - set(EXPECTED)
    assert not missing, f'corpus files without an EXPECTED.yaml entry: {sorted(missing)}'
    assert len(EXPECTED) >= 30
    assert len(committed) >= 30
    # every committed file is text (binary cases are generated, not committed)
    for name in committed:
        (CORPUS / name).read_bytes().decode('utf-8')


def test_expected_entries_exist(generated):
    committed = {p.name for p in CORPUS.iterdir()} - NOT_CASES
    unknown = set(EXPECTED) - committed - set(generated)
    assert not unknown, f'EXPECTED.yaml names cases that exist nowhere: {sorted(unknown)}'
    assert not committed & set(generated), 'a case is both committed and generated'


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_corpus_case_raises_data_format_error(name, request):
    path = CORPUS / name
    if not path.exists():
        path = request.getfixturevalue('generated')[name]
    # pytest.raises(DataFormatError) lets any other exception type fail the test
    with pytest.raises(DataFormatError) as info:
        io.read_any(path)
    err = info.value
    message = str(err)
    assert isinstance(err, ValueError)
    assert name in message
    assert re.search(EXPECTED[name], message), f'{message!r} does not match {EXPECTED[name]!r}'
    line = re.match(r'.*?\.(?:csv|yaml):(\d+): ', message)
    if line:
        assert err.line == int(line.group(1))
    if "topic '" in message:
        assert err.topic is not None and err.topic in message
    assert 'Traceback' not in message


@pytest.mark.parametrize('name', sorted(n for n in EXPECTED if n.endswith('.csv')
                                        and (CORPUS / n).is_file()))
def test_corpus_text_case_with_specific_reader(name):
    reader = io.read_frf if name.startswith('frf_') else io.read_timeseries
    with pytest.raises(DataFormatError) as info:
        reader(CORPUS / name)
    assert name in str(info.value)


# ---------------------------------------------------------------------------
# Text formats: parsing
# ---------------------------------------------------------------------------
def test_valid_timeseries_parsed(tmp_path):
    p = tmp_path / 'valid.csv'
    p.write_text(VALID_TS)
    ts = io.read_timeseries(p)
    assert ts.path == str(p)
    assert ts.sample == 'slim'
    assert ts.geometry == Geometry(0.022, 0.007, 0.00036, 'slim')
    assert ts.known == {'temperature_k': 298.15, 'youngs_modulus_pa': 5.71e8,
                        'surface_resistance_ohm': 6.05}
    assert ts.extra == {'operator': 'jd', 'rig.id': 'shaker-2'}
    assert ts.sample_rate_hz == 1000.0
    assert ts.time_s.tolist() == [0.0, 0.001, 0.002, 0.003]
    assert ts.deflection_m.tolist() == [0.0, 1e-5, 2e-5, 3e-5]
    assert ts.current_a.tolist() == [0.0, 2e-8, -4e-8, 6e-8]
    assert ts.deflection_alignment == 'exact'
    assert ts.n_samples == 4 and ts.has_deflection
    assert ts.duration_s == pytest.approx(0.003)


def test_crlf_bom_spaces_and_trailing_blank_lines_accepted(tmp_path):
    p = tmp_path / 'crlf.csv'
    text = VALID_TS.replace('0.001,1.0e-05,2.0e-08', ' 0.001 , 1.0e-05 ,2.0e-08 ')
    p.write_bytes(b'\xef\xbb\xbf' + (text + '\n\n').replace('\n', '\r\n').encode())
    ts = io.read_timeseries(p)
    assert ts.time_s.tolist() == [0.0, 0.001, 0.002, 0.003]
    assert ts.extra['operator'] == 'jd'


def test_deflection_column_optional(tmp_path):
    p = tmp_path / 'field.csv'
    p.write_text('# format: ipmc-timeseries/1\n# length_m: 0.011\n# width_m: 0.007\n'
                 '# thickness_m: 0.00036\ntime_s,current_A\n10.0,1e-8\n10.002,2e-8\n10.004,3e-8\n')
    ts = io.read_any(p)
    assert isinstance(ts, io.TimeSeries)
    assert ts.deflection_m is None and not ts.has_deflection
    assert ts.deflection_alignment is None
    assert ts.sample == '' and ts.known == {} and ts.extra == {}
    assert ts.sample_rate_hz == pytest.approx(500.0)
    assert ts.current_a.tolist() == [1e-8, 2e-8, 3e-8]


def test_sample_rate_tolerance(tmp_path):
    p = tmp_path / 'rate.csv'
    p.write_text(VALID_TS.replace('sample_rate_hz: 1000', 'sample_rate_hz: 1009'))
    assert io.read_timeseries(p).sample_rate_hz == 1009.0  # within 1 %: kept as given
    p.write_text(VALID_TS.replace('sample_rate_hz: 1000', 'sample_rate_hz: 1015'))
    with pytest.raises(DataFormatError, match=r'rate\.csv:7: sample_rate_hz = 1015\.0 disagrees'):
        io.read_timeseries(p)


def test_wrong_reader_names_the_format_line(tmp_path):
    ts_path = tmp_path / 't.csv'
    ts_path.write_text(VALID_TS)
    with pytest.raises(DataFormatError, match=r"t\.csv:1: format is 'ipmc-timeseries/1', "
                                              r"expected 'ipmc-frf/1'"):
        io.read_frf(ts_path)
    frf_path = tmp_path / 'f.csv'
    io.write_frf(frf_path, _frf())
    with pytest.raises(DataFormatError, match=r"f\.csv:1: format is 'ipmc-frf/1'"):
        io.read_timeseries(frf_path)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(DataFormatError, match=r'nope\.csv: file not found') as info:
        io.read_timeseries(tmp_path / 'nope.csv')
    assert info.value.line is None
    with pytest.raises(DataFormatError, match=r'is a directory'):
        io.read_timeseries(tmp_path)
    with pytest.raises(DataFormatError, match=r'nope\.csv: file not found'):
        io.read_any(tmp_path / 'nope.csv')
    with pytest.raises(DataFormatError, match=r'nope\.mcap: bag not found'):
        io.read_any(tmp_path / 'nope.mcap')


def test_error_format_attributes_and_pickle():
    err = DataFormatError('data/x.csv', 17, "non-numeric cell 'abc' in column current_A")
    assert str(err) == "data/x.csv:17: non-numeric cell 'abc' in column current_A"
    assert (err.path, err.line, err.topic) == ('data/x.csv', 17, None)
    bag = DataFormatError('run1', None, "has message type 'x'", topic='/current')
    assert str(bag) == "run1: topic '/current': has message type 'x'"
    back = pickle.loads(pickle.dumps(bag))
    assert (str(back), back.path, back.line, back.topic) == (str(bag), 'run1', None, '/current')
    assert isinstance(err, ValueError)


def test_workbench_io_imports_without_rclpy_or_rosbags():
    code = ('import sys, ipmc_sensor_ros.workbench.io; '
            "bad = [m for m in ('rclpy', 'rosbags') if m in sys.modules]; "
            'assert not bad, bad')
    subprocess.run([sys.executable, '-c', code], check=True, cwd=HERE.parent)


# ---------------------------------------------------------------------------
# Text formats: round trips
# ---------------------------------------------------------------------------
@pytest.mark.parametrize('deflection', [True, False])
def test_timeseries_round_trip_exact(tmp_path, deflection):
    ts = _series(deflection=deflection, known={'temperature_k': 300.0,
                                               'surface_resistance_ohm': 0.0},
                 extra={'operator': 'jd', 'note': 'run 4: 10 Hz sine'})
    p = tmp_path / 'rt.csv'
    io.write_timeseries(p, ts)
    back = io.read_timeseries(p)
    _assert_same_ts(ts, back)
    assert back.path == str(p)
    assert p.read_text().startswith('# format: ipmc-timeseries/1\n# sample: slim\n')


finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    steps=st.lists(st.floats(min_value=1e-6, max_value=10.0), min_size=1, max_size=30),
    t0=st.floats(min_value=-1e6, max_value=2e9),
    data=st.data(),
)
def test_timeseries_round_trip_property(tmp_path, steps, t0, data):
    t = t0 + np.cumsum([0.0] + steps)
    if np.any(np.diff(t) <= 0):  # steps lost to float rounding at large t0
        return
    n = t.size
    current = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))
    deflection = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))
    ts = io.TimeSeries(path='', sample='big', geometry=PAPER_SAMPLES['big'], known={},
                       sample_rate_hz=1.0 / float(np.median(np.diff(t))), time_s=t,
                       current_a=current, deflection_m=deflection)
    p = tmp_path / 'prop.csv'
    io.write_timeseries(p, ts)
    _assert_same_ts(ts, io.read_timeseries(p))


def test_write_timeseries_refuses_invalid(tmp_path):
    ts = _series(n=5)
    bad = io.TimeSeries(path='', sample='s', geometry=ts.geometry, known={},
                        sample_rate_hz=1000.0, time_s=[0.0, 0.001, 0.001, 0.002, 0.003],
                        current_a=np.zeros(5))
    p = tmp_path / 'bad.csv'
    with pytest.raises(DataFormatError, match=r'refusing to write an invalid time series: '
                                              r'duplicate time'):
        io.write_timeseries(p, bad)
    assert not p.exists()
    nan = io.TimeSeries(path='', sample='s', geometry=ts.geometry, known={},
                        sample_rate_hz=1000.0, time_s=ts.time_s, current_a=[0, 1, math.nan, 0, 0])
    with pytest.raises(DataFormatError, match='NaN/Inf'):
        io.write_timeseries(p, nan)
    with pytest.raises(DataFormatError, match='one line'):
        io.write_timeseries(p, _series(n=5, extra={'note': 'two\nlines'}))


def _frf(coherence=True, std=True):
    f = np.geomspace(0.1, 100.0, 12)
    return io.FrequencyResponseData(
        path='', sample='big', geometry=PAPER_SAMPLES['big'], known={'youngs_modulus_pa': 5.71e8},
        frequency_hz=f, gain_a_per_m=1e-4 * f / (1 + f), phase_deg=90.0 - np.rad2deg(np.arctan(f)),
        coherence=np.linspace(0.5, 1.0, f.size) if coherence else None,
        gain_std_a_per_m=1e-6 * np.ones(f.size) if std else None,
        phase_std_deg=0.5 * np.ones(f.size) if std else None, extra={'excitation': 'chirp'})


@pytest.mark.parametrize('coherence', [True, False])
@pytest.mark.parametrize('std', [True, False])
def test_frf_round_trip_exact(tmp_path, coherence, std):
    frf = _frf(coherence, std)
    p = tmp_path / 'frf.csv'
    io.write_frf(p, frf)
    header = [ln for ln in p.read_text().splitlines() if not ln.startswith('#')][0]
    assert header == ','.join(['frequency_hz', 'gain_A_per_m', 'phase_deg']
                              + (['coherence'] if coherence else [])
                              + (['gain_std_A_per_m', 'phase_std_deg'] if std else []))
    back = io.read_any(p)
    assert isinstance(back, io.FrequencyResponseData)
    assert (back.sample, back.geometry, back.known, back.extra) == \
        (frf.sample, frf.geometry, frf.known, frf.extra)
    for name in ('frequency_hz', 'gain_a_per_m', 'phase_deg', 'coherence', 'gain_std_a_per_m',
                 'phase_std_deg'):
        a, b = getattr(frf, name), getattr(back, name)
        assert (a is None and b is None) or np.array_equal(a, b), name
    assert back.gain_std is back.gain_std_a_per_m
    np.testing.assert_allclose(back.response,
                               frf.gain_a_per_m * np.exp(1j * np.deg2rad(frf.phase_deg)))


def test_frf_response_property():
    frf = io.FrequencyResponseData(path='', sample='', geometry=PAPER_SAMPLES['big'], known={},
                                   frequency_hz=[1.0, 2.0], gain_a_per_m=[2.0, 3.0],
                                   phase_deg=[90.0, -180.0])
    np.testing.assert_allclose(frf.response, [2j, -3.0], atol=1e-12)


# ---------------------------------------------------------------------------
# Robustness: random damage never escapes as another exception type
# ---------------------------------------------------------------------------
@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_damaged_files_raise_only_data_format_error(tmp_path, data):
    text = VALID_TS.encode()
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(text)))
        op = data.draw(st.sampled_from(['delete', 'insert', 'replace']))
        chunk = data.draw(st.binary(min_size=1, max_size=4) | st.sampled_from(
            [b',', b'\n', b'#', b':', b'nan', b'-', b'e', b'9', b' ', b'\r', b'\xff']))
        if op == 'delete':
            text = text[:pos] + text[pos + len(chunk):]
        elif op == 'insert':
            text = text[:pos] + chunk + text[pos:]
        else:
            text = text[:pos] + chunk + text[pos + len(chunk):]
    p = tmp_path / 'damaged.csv'
    p.write_bytes(text)
    try:
        result = io.read_any(p)
    except DataFormatError as err:
        assert 'damaged.csv' in str(err)
    else:
        # whatever survives the damage is still valid data
        if isinstance(result, io.TimeSeries):
            assert result.n_samples >= 2 and np.all(np.diff(result.time_s) > 0)
            assert np.all(np.isfinite(result.current_a))
        else:
            assert isinstance(result, io.FrequencyResponseData)
            assert np.all(result.frequency_hz > 0) and np.all(result.gain_a_per_m > 0)


# ---------------------------------------------------------------------------
# Bags
# ---------------------------------------------------------------------------
@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_bag_round_trip(tmp_path, storage, make_bags):
    ts = _series(n=333, known={'temperature_k': 300.0}, extra={'operator': 'jd'})
    bag = tmp_path / f'run_{storage}'
    io.write_bag(bag, ts, storage=storage, block_size=50)
    assert (bag / 'ipmc.yaml').is_file()
    back = io.read_bag(bag)
    _assert_same_ts(ts, back, rate_exact=False)
    assert back.deflection_alignment == 'exact'
    assert back.path == str(bag)
    # the bare storage file reads the same (sidecar found beside it)
    storage_file = next(bag.glob('*.mcap' if storage == 'mcap' else '*.db3'))
    _assert_same_ts(ts, io.read_any(storage_file), rate_exact=False)
    # topics match with or without the leading slash
    again = io.read_bag(bag, current_topic='/current', deflection_topic='/deflection_truth')
    assert np.array_equal(again.deflection_m, ts.deflection_m)


def _raw_current_bag(bag, payloads, geometry_sidecar=True):
    """Write ``payloads`` (CDR bytes) on /current, stamped 1 ms apart, with a sidecar."""
    from rosbags.rosbag2 import Writer

    from ipmc_sensor_ros.workbench.bagtopics import bag_typestore, MULTIARRAY_TYPE

    with Writer(bag, version=8) as writer:
        conn = writer.add_connection('/current', MULTIARRAY_TYPE, typestore=bag_typestore())
        for k, raw in enumerate(payloads):
            writer.write(conn, 1_000_000_000 + 1_000_000 * k, raw)
    (bag / 'ipmc.yaml').write_text('geometry: {length_m: 0.022, width_m: 0.007, '
                                   'thickness_m: 0.00036}\n')


def test_one_sample_bags_read_from_their_bytes_as_blocks_are(tmp_path, make_bags):
    """
    One message per sample (a DAQ driver's bag) reads like the same samples in blocks.

    Through the byte path (``OneSampleCodec``, 17x faster than deserialising each message);
    runs of one-sample messages mixed with blocks, and the errors name the message as the
    general path does.
    """
    from ipmc_sensor_ros.interface.blocks import CURRENT_COLUMNS
    from ipmc_sensor_ros.interface.cdr import OneSampleCodec

    ts = _series(n=120)
    one, blocks = tmp_path / 'one', tmp_path / 'blocks'
    io.write_bag(one, ts, block_size=1)
    io.write_bag(blocks, ts, block_size=50)
    a, b = io.read_bag(one), io.read_bag(blocks)
    for field in ('time_s', 'current_a', 'deflection_m'):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    codec = OneSampleCodec(CURRENT_COLUMNS)
    block = _first_current_message(blocks)                      # a 50-sample block first
    t0 = float(ts.time_s[49])
    tail = [codec.encode(t0 + 1e-3 * (k + 1), 1e-7 * k) for k in range(5)]
    _raw_current_bag(tmp_path / 'mixed', [block] + tail)
    mixed = io.read_bag(tmp_path / 'mixed')
    assert np.array_equal(mixed.time_s, np.r_[ts.time_s[:50], t0 + 1e-3 * np.arange(1, 6)])
    assert np.array_equal(mixed.current_a, np.r_[ts.current_a[:50], 1e-7 * np.arange(5)])
    bad = {'nan': ([codec.encode(1.0, 0.0), codec.encode(1.001, math.nan)],
                   r'message 2, sample 0: NaN/Inf'),
           'order': ([codec.encode(1.0, 0.0), codec.encode(1.001, 0.0), codec.encode(1.0005, 0.0)],
                     r'message 3 starts at 1\.0005 s, not after .* 1\.001 s'),
           'after_block': ([block, codec.encode(t0, 0.0)], r'message 2 starts at')}
    for name, (payloads, match) in bad.items():
        _raw_current_bag(tmp_path / name, payloads)
        with pytest.raises(DataFormatError, match=match):
            io.read_bag(tmp_path / name)


def _first_current_message(bag) -> bytes:
    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == '/current']
        for _conn, _stamp, raw in reader.messages(connections=conns):
            return bytes(raw)


def test_bag_geometry_argument_and_sidecar_options(tmp_path, make_bags):
    ts = _series(n=20)
    bag = tmp_path / 'nosidecar'
    io.write_bag(bag, ts, sidecar=False)
    with pytest.raises(DataFormatError, match=r'nosidecar: no geometry'):
        io.read_bag(bag)
    geo = PAPER_SAMPLES['short']
    assert io.read_bag(bag, geometry=geo).geometry == geo
    assert io.read_bag(bag, geometry=geo.to_dict()).geometry == geo
    with pytest.raises(DataFormatError, match=r"geometry argument: .*'length_m' = 11\.0 m"):
        io.read_bag(bag, geometry={'length_m': 11.0, 'width_m': 0.007, 'thickness_m': 3.6e-4})
    side = tmp_path / 'elsewhere.yaml'
    side.write_text('geometry: {length_m: 0.011, width_m: 0.007, thickness_m: 0.00036, '
                    'name: short}\nmaterial: {temperature_k: 290.0}\n')
    got = io.read_bag(bag, sidecar=side)
    assert got.geometry == geo and got.sample == 'short' and got.known == {'temperature_k': 290.0}
    with pytest.raises(
        DataFormatError, match=r'missing\.yaml: sidecar of bag .*nosidecar.* not found'
    ):
        io.read_bag(bag, sidecar=tmp_path / 'missing.yaml')


def test_bag_without_deflection(tmp_path, make_bags):
    ts = _series(n=30, deflection=False)
    bag = tmp_path / 'field'
    io.write_bag(bag, ts, storage='mcap')
    back = io.read_bag(bag)
    assert back.deflection_m is None and back.deflection_alignment is None
    assert io.read_bag(bag, deflection_topic=None).deflection_m is None
    with pytest.raises(DataFormatError, match=r"field: topic 'deflection_truth': deflection topic "
                                              r'not found; the bag has: /current'):
        io.read_bag(bag, require_deflection=True)


def test_bag_estimated_deflection_topic(tmp_path, make_bags):
    ts = _series(n=30)
    bag = tmp_path / 'estimated'
    io.write_bag(bag, ts, deflection_topic='deflection/block')
    back = io.read_bag(bag, deflection_topic='deflection/block')
    assert back.deflection_alignment == 'exact'
    assert np.array_equal(back.deflection_m, ts.deflection_m)


def test_bag_point_stamped_exact(tmp_path, make_bags):
    ts = _series(n=60, t0=1.7e9)  # epoch-like times: float seconds vs integer nanoseconds
    bag = tmp_path / 'points'
    io.write_bag(bag, ts, deflection_msgtype=io.POINT_STAMPED_TYPE)
    back = io.read_bag(bag)
    assert back.deflection_alignment == 'exact'
    assert np.array_equal(back.deflection_m, ts.deflection_m)
    assert np.array_equal(back.time_s, ts.time_s)


def test_bag_interpolation_flag(tmp_path, make_bags):
    t = 0.001 + np.arange(11) / 1000.0
    current = 1e-7 * np.arange(11)
    # ground truth at 500 Hz, shifted by 0.25 ms, covering the current span
    td = np.arange(0.00075, 0.0135, 0.002)
    assert td[0] < t[0] and td[-1] > t[-1]
    zd = 1e-3 * np.sin(300 * td)
    bag = make_bags.raw_bag(tmp_path / 'interp', [
        ('/current', io.MULTIARRAY_TYPE, [(10**6, make_bags.block_msg(t[:6], current[:6])),
                                          (2 * 10**6, make_bags.block_msg(t[6:], current[6:]))]),
        ('/deflection_truth', io.POINT_STAMPED_TYPE,
         [(int(x * 1e9) + 10**6, make_bags.point_msg(x + 0.0, z)) for x, z in
          zip(td[::-1] + 0.0, zd[::-1])]),  # out of order on purpose: sorted by stamp
    ])
    back = io.read_bag(bag, geometry=PAPER_SAMPLES['slim'])
    assert back.deflection_alignment == 'linear'
    td_ns = np.round(td * 1e9) / 1e9
    np.testing.assert_allclose(back.deflection_m, np.interp(t, td_ns, zd), rtol=0, atol=1e-15)
    assert np.array_equal(back.time_s, t) and np.array_equal(back.current_a, current)

    # a denser truth that contains every current time aligns exactly
    t2 = 0.001 + np.arange(21) / 2000.0
    dense = make_bags.raw_bag(tmp_path / 'dense', [
        ('/current', io.MULTIARRAY_TYPE, [(10**6, make_bags.block_msg(t, current))]),
        ('/deflection_truth', io.MULTIARRAY_TYPE,
         [(10**6, make_bags.block_msg(t2, 2 * t2, label=io.DEFLECTION_LABEL))]),
    ])
    exact = io.read_bag(dense)
    assert exact.deflection_alignment == 'exact'
    np.testing.assert_array_equal(exact.deflection_m, 2 * t2[::2])


def test_write_bag_argument_checks(tmp_path, make_bags):
    ts = _series(n=10)
    with pytest.raises(ValueError, match='storage'):
        io.write_bag(tmp_path / 'a', ts, storage='bag')
    with pytest.raises(ValueError, match='block_size'):
        io.write_bag(tmp_path / 'b', ts, block_size=0)
    io.write_bag(tmp_path / 'c', ts)
    with pytest.raises(FileExistsError):
        io.write_bag(tmp_path / 'c', ts)
    with pytest.raises(ValueError, match='>= 0'):
        io.write_bag(tmp_path / 'd', _series(n=10, t0=-1.0))


def test_read_any_and_load_many(tmp_path, make_bags):
    ts_path = tmp_path / 'a.csv'
    io.write_timeseries(ts_path, _series(n=10))
    frf_path = tmp_path / 'b.csv'
    io.write_frf(frf_path, _frf())
    bag = tmp_path / 'c'
    io.write_bag(bag, _series(n=10))
    loaded = io.load_many([ts_path, str(frf_path), bag])
    assert [type(x) for x in loaded] == [io.TimeSeries, io.FrequencyResponseData, io.TimeSeries]
    bad = tmp_path / 'bad.csv'
    bad.write_text('hello\n')
    with pytest.raises(DataFormatError, match=r"bad\.csv:1: missing '# format"):
        io.load_many([ts_path, bad])
