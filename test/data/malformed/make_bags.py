# SPDX-License-Identifier: Apache-2.0
"""
Generate the binary members of the malformed-input corpus (bags, non-UTF-8 files).

Binary files are not committed: ``test/test_workbench_io.py`` calls
:func:`make_all` into a temporary directory.  Each case is named after what is
wrong with it; ``EXPECTED.yaml`` beside this file maps every name to the regex
its error message must match.  Run ``python make_bags.py OUTDIR`` to inspect
them by hand.
"""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ''):  # run as a script: make the package importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

from ipmc_sensor_ros.physics.parameters import Geometry  # noqa: E402
from ipmc_sensor_ros.workbench import io  # noqa: E402

GEOMETRY = Geometry(0.022, 0.007, 0.00036, 'slim')


def _series(n: int = 40, rate_hz: float = 1000.0) -> io.TimeSeries:
    t = np.arange(n) / rate_hz
    return io.TimeSeries(path='', sample='slim', geometry=GEOMETRY, known={},
                         sample_rate_hz=rate_hz, time_s=t,
                         current_a=1e-7 * np.sin(2 * np.pi * 10 * t),
                         deflection_m=1e-3 * np.cos(2 * np.pi * 10 * t))


def raw_bag(path: Path, messages, storage: str = 'sqlite3', sidecar: bool = True) -> Path:
    """
    Return a bag with hand-made messages.

    ``messages`` = [(topic, msgtype, [(stamp_ns, msg)])].
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = io.bag_typestore()
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        for topic, msgtype, items in messages:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for stamp, msg in items:
                writer.write(conn, stamp, store.serialize_cdr(msg, msgtype))
    if sidecar:
        (path / 'ipmc.yaml').write_text(
            'geometry: {length_m: 0.022, width_m: 0.007, thickness_m: 0.00036, name: slim}\n')
    return path


def block_msg(times, values, label=io.CURRENT_LABEL, size=None, stride=None):
    store = io.bag_typestore()
    T = store.types
    t = np.asarray(times, float)
    n = t.size
    data = np.empty(2 * n)
    data[0::2], data[1::2] = t, values
    layout = T['std_msgs/msg/MultiArrayLayout'](
        dim=[
            T['std_msgs/msg/MultiArrayDimension'](
                label='sample',
                size=n if size is None else size,
                stride=2 * n if stride is None else stride,
            ),
            T['std_msgs/msg/MultiArrayDimension'](label=label, size=2, stride=2),
        ],
        data_offset=0,
    )
    return T[io.MULTIARRAY_TYPE](layout=layout, data=data)


def point_msg(t: float, z: float):
    """Return a ``PointStamped`` deflection sample: ``z`` metres at ``t`` seconds."""
    T = io.bag_typestore().types
    sec, nsec = divmod(int(round(t * 1e9)), 10**9)
    return T[io.POINT_STAMPED_TYPE](
        header=T['std_msgs/msg/Header'](
            stamp=T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nsec), frame_id='tip'
        ),
        point=T['geometry_msgs/msg/Point'](x=0.0, y=0.0, z=z),
    )


def _cut_half(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def make_all(outdir: str | Path) -> dict[str, Path]:
    """Create every generated case in ``outdir``; return {case name: path}."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    cases: dict[str, Path] = {}
    ts = _series()
    store = io.bag_typestore()
    T = store.types

    # -- not text -------------------------------------------------------------
    p = out / 'binary_garbage.csv'
    p.write_bytes(b'\x89PNG\r\n\x1a\n' + bytes(range(256)) * 4)
    cases[p.name] = p
    p = out / 'latin1_header.csv'  # valid text, but Latin-1 on line 2
    p.write_bytes('# format: ipmc-timeseries/1\n# sample: M\xfcller\n'.encode('latin-1'))
    cases[p.name] = p
    p = out / 'nul_bytes.csv'
    p.write_bytes(b'# format: ipmc-timeseries/1\n# sample: a\x00b\n')
    cases[p.name] = p
    p = out / 'directory_given.csv'  # a directory where a file is expected
    p.mkdir()
    cases[p.name] = p

    # -- bags: structure ------------------------------------------------------
    p = out / 'bag_missing_current_topic'
    io.write_bag(p, ts, current_topic='ipmc/current_raw')
    cases[p.name] = p

    p = out / 'bag_current_wrong_type'
    raw_bag(p, [('/current', 'std_msgs/msg/String',
                 [(1000, T['std_msgs/msg/String'](data='0.0,1e-7'))])])
    cases[p.name] = p

    p = out / 'bag_deflection_wrong_type'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE, [(1000, block_msg([0.0, 0.001], [0.0, 1e-7]))]),
                ('/deflection_truth', 'std_msgs/msg/Float64',
                 [(1000, T['std_msgs/msg/Float64'](data=1e-3))])])
    cases[p.name] = p

    p = out / 'bag_truncated_mcap'
    io.write_bag(p, ts, storage='mcap')
    _cut_half(p / 'bag_truncated_mcap.mcap')
    cases[p.name] = p

    p = out / 'bag_truncated_file.mcap'  # a bare storage file, cut
    tmp = out / '_tmp_mcap'
    io.write_bag(tmp, ts, storage='mcap')
    shutil.copyfile(tmp / '_tmp_mcap.mcap', p)
    shutil.rmtree(tmp)
    _cut_half(p)
    cases[p.name] = p

    p = out / 'bag_truncated_db3'  # sqlite3 database cut in half
    io.write_bag(p, _series(3000), storage='sqlite3')
    _cut_half(p / 'bag_truncated_db3.db3')
    cases[p.name] = p

    p = out / 'bag_garbage_db3'  # metadata fine, database overwritten with garbage
    io.write_bag(p, ts, storage='sqlite3')
    (p / 'bag_garbage_db3.db3').write_bytes(b'garbage, not SQLite ' * 200)
    cases[p.name] = p

    p = out / 'bag_garbage_file.db3'
    p.write_bytes(bytes((i * 37 + 11) % 256 for i in range(4096)))
    cases[p.name] = p

    p = out / 'bag_no_metadata'
    io.write_bag(p, ts, storage='sqlite3')
    (p / 'metadata.yaml').unlink()
    cases[p.name] = p

    p = out / 'bag_metadata_lists_missing_file'
    io.write_bag(p, ts, storage='sqlite3')
    (p / 'bag_metadata_lists_missing_file.db3').unlink()
    cases[p.name] = p

    # -- bags: geometry ---------------------------------------------------------
    p = out / 'bag_missing_geometry'
    io.write_bag(p, ts, sidecar=False)
    cases[p.name] = p

    p = out / 'bag_sidecar_length_in_mm'
    io.write_bag(p, ts, sidecar=False)
    (p / 'ipmc.yaml').write_text('geometry:\n  length_m: 22\n  width_m: 7\n  thickness_m: 0.36\n')
    cases[p.name] = p

    p = out / 'bag_sidecar_bad_yaml'
    io.write_bag(p, ts, sidecar=False)
    (p / 'ipmc.yaml').write_text('geometry:\n  length_m: 0.022\n   width_m: [0.007\n')
    cases[p.name] = p

    p = out / 'bag_sidecar_unknown_key'
    io.write_bag(p, ts, sidecar=False)
    (p / 'ipmc.yaml').write_text('geometry: {length_m: 0.022, width_m: 0.007, thickness_m: '
                                 '0.00036}\ngeometrie: {length_m: 0.01}\n')
    cases[p.name] = p

    # -- bags: message content ----------------------------------------------------
    p = out / 'bag_current_wrong_label'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE,
                 [(1000, block_msg([0.0, 0.001], [0.0, 1e-7], label='time_s,current_uA'))])])
    cases[p.name] = p

    p = out / 'bag_current_layout_mismatch'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE,
                 [(1000, block_msg([0.0, 0.001, 0.002], [0.0, 1e-7, 2e-7], size=4))])])
    cases[p.name] = p

    p = out / 'bag_current_values_only'
    m = T[io.MULTIARRAY_TYPE](layout=T['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
                              data=np.array([0.0, 1e-7, 2e-7]))
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE, [(1000, m)])])
    cases[p.name] = p

    p = out / 'bag_current_time_backwards'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE,
                 [(1000, block_msg([0.010, 0.011], [0.0, 1e-7])),
                  (2000, block_msg([0.005, 0.006], [0.0, 1e-7]))])])
    cases[p.name] = p

    p = out / 'bag_current_nan'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE,
                 [(1000, block_msg([0.0, 0.001, 0.002], [0.0, np.nan, 1e-7]))])])
    cases[p.name] = p

    p = out / 'bag_current_empty_topic'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE, [])])
    cases[p.name] = p

    p = out / 'bag_deflection_wrong_label'
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE, [(1000, block_msg([0.0, 0.001], [0.0, 1e-7]))]),
                ('/deflection_truth', io.MULTIARRAY_TYPE,
                 [(1000, block_msg([0.0, 0.001], [0.0, 1e-7], label=io.CURRENT_LABEL))])])
    cases[p.name] = p

    p = out / 'bag_deflection_not_covering'  # truth starts late: would need extrapolation
    pts = [(int(round(t * 1e9)), point_msg(t, 1e-3)) for t in (0.0015, 0.0025, 0.0035)]
    raw_bag(p, [('/current', io.MULTIARRAY_TYPE,
                 [(1000, block_msg([0.0, 0.001, 0.002, 0.003], [0.0, 1e-7, 2e-7, 3e-7]))]),
                ('/deflection_truth', io.POINT_STAMPED_TYPE, pts)])
    cases[p.name] = p
    return cases


if __name__ == '__main__':
    if len(sys.argv) != 2:
        sys.exit('usage: make_bags.py OUTDIR')
    for name, path in make_all(sys.argv[1]).items():
        print(name, path)
