# SPDX-License-Identifier: Apache-2.0
"""
rosbag2 bags in and out of the workbench (read with ``rosbags``; no rclpy needed).

Holds the bag as a whole: :func:`read_bag` (open a bag directory or storage
file, pick its topics, attach the geometry), the ``ipmc.yaml`` sidecar, and
:func:`write_bag`.  The messages of one topic (types, decoding, validation,
alignment of the deflection to the current) are read by :mod:`.bagtopics`.

Bags (rosbag2, read with ``rosbags``)
=====================================
``read_bag`` accepts a bag directory (with ``metadata.yaml``) or a single
``.mcap``/``.db3`` storage file.  Topics are matched with or without the
leading ``/``.

* current (default topic ``current``): ``std_msgs/msg/Float64MultiArray``
  blocks, ``layout.dim[0] = (label "sample", size n, stride 2n)``,
  ``layout.dim[1] = (label "time_s,current_A", size 2, stride 2)``,
  ``data = [t0, i0, t1, i1, ...]`` (seconds, amperes).  Samples must be
  strictly increasing in time in message order.
* deflection (default topic ``deflection_truth``; the estimator's output
  ``deflection/block`` has the same layout): the same block type with label
  ``"time_s,deflection_m"`` (metres), or ``geometry_msgs/msg/PointStamped``
  with ``point.z`` the deflection (m) at ``header.stamp``.  The deflection is
  aligned to the current sample times: ``deflection_alignment = "exact"`` when
  every current time has a deflection sample at the same time (within 1 ns
  plus float rounding, as when both come from the simulator), otherwise
  ``"linear"`` (linear interpolation; the deflection must cover the whole
  current time span, no extrapolation).  A missing deflection topic gives
  ``deflection_m = None`` unless ``require_deflection=True``.
* geometry: the ``geometry`` argument (refused where the sidecar holds another), else the
  YAML sidecar (argument
  ``sidecar``, default ``<bag dir>/ipmc.yaml``, for a single storage file the
  ``ipmc.yaml`` beside it)::

      geometry: {length_m: 0.022, width_m: 0.007, thickness_m: 0.00036, name: slim}
      material: {temperature_k: 300.0}     # optional, partial; -> known
      extra: {operator: jd}                # optional -> extra
"""
from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..interface.blocks import SAMPLE_LABEL
from ..physics.parameters import Geometry, MaterialParameters, ParameterError
from .bagtopics import (
    align_deflection,
    bag_typestore,
    CURRENT_LABEL,
    DEFLECTION_LABEL,
    describe_topics,
    find_topic,
    MULTIARRAY_TYPE,
    POINT_STAMPED_TYPE,
    read_topic,
    topic_key,
)
from .measurements import DataFormatError, PathLike, TimeSeries
from .stamps import measured_rate_hz

__all__ = ['read_bag', 'write_bag', 'same_geometry']

SIDECAR_NAME = 'ipmc.yaml'
_SIDECAR_KEYS = ('geometry', 'material', 'extra', 'model')


def _yaml_line(text: str, keys: Sequence[str]) -> int | None:
    """1-based line of the nested mapping key ``keys`` in YAML ``text`` (best effort)."""
    import yaml

    try:
        node = yaml.compose(text)
    except yaml.YAMLError:
        return None
    line = None
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            break
        for k, v in node.value:
            if getattr(k, 'value', None) == key:
                line, node = k.start_mark.line + 1, v
                break
        else:
            break
    return line


def same_geometry(where: str, own, given) -> None:
    """Refuse a geometry argument that disagrees with the one ``where`` holds (to 1 ppm)."""
    keys = ('length_m', 'width_m', 'thickness_m')
    mine = [float(getattr(own, k)) for k in keys]
    theirs = [float(given[k] if isinstance(given, dict) else getattr(given, k)) for k in keys]
    if not np.allclose(mine, theirs, rtol=1e-6, atol=0.0):
        raise DataFormatError(where, None, 'the geometry given (--geometry: ' + ', '.join(
            f'{k} {v:g}' for k, v in zip(keys, theirs)) + ") disagrees with the file's (" +
            ', '.join(f'{k} {v:g}' for k, v in zip(keys, mine)) + '): drop one of them')


def _read_sidecar(bag: str, path: Path, need_geometry: bool):
    """(geometry or None, known, extra) from a YAML sidecar."""
    import yaml

    where = str(path)
    about = f"sidecar of bag '{bag}'"
    if path.exists() and not path.is_file():
        raise DataFormatError(where, None, f'{about} is not a regular file: refusing to read it')
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise DataFormatError(where, None, f'{about} not found') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(where, None, f'cannot read {about}: {exc}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        problem = getattr(exc, 'problem', None) or exc
        raise DataFormatError(where, mark.line + 1 if mark else None,
                              f'{about} is not valid YAML: {problem}') from None
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise DataFormatError(where, 1, f"{about} must be a mapping with a 'geometry' key")
    unknown = sorted(str(k) for k in set(data) - set(_SIDECAR_KEYS))
    if unknown:
        raise DataFormatError(where, _yaml_line(text, [unknown[0]]), f'unknown key(s) {unknown} '
                              f'in {about}; known: {list(_SIDECAR_KEYS)}')
    geometry = None
    if data.get('geometry') is not None:
        g = data['geometry']
        if not isinstance(g, dict):
            raise DataFormatError(where, _yaml_line(text, ['geometry']),
                                  f"'geometry' in {about} must be a mapping")
        try:
            geometry = Geometry.from_dict(g)
        except (ParameterError, TypeError) as exc:
            m = re.search(r"parameter '(\w+)'", str(exc))
            line = _yaml_line(text, ['geometry', m.group(1)] if m else ['geometry'])
            raise DataFormatError(where, line, f'geometry in {about}: {exc}') from None
    elif need_geometry:
        raise DataFormatError(where, None, f"{about} has no 'geometry' (length_m, width_m, "
                              'thickness_m in metres) and no geometry was passed')
    known: dict[str, float] = {}
    if data.get('material') is not None:
        mat = data['material']
        if not isinstance(mat, dict):
            raise DataFormatError(where, _yaml_line(text, ['material']),
                                  f"'material' in {about} must be a mapping")
        try:
            MaterialParameters.from_dict(mat)
        except (ParameterError, TypeError) as exc:
            raise DataFormatError(where, _yaml_line(text, ['material']),
                                  f'material in {about}: {exc}') from None
        known = {str(k): float(v) for k, v in mat.items()}
    extra = data.get('extra') or {}
    if not isinstance(extra, dict):
        raise DataFormatError(where, _yaml_line(text, ['extra']),
                              f"'extra' in {about} must be a mapping")
    extra = dict(extra)
    if 'model' in data:
        extra['model'] = data['model']
    return geometry, known, extra


def read_bag(path: PathLike, current_topic: str = 'current',
             deflection_topic: str | None = 'deflection_truth',
             geometry: Geometry | Mapping[str, Any] | None = None,
             sidecar: PathLike | None = None, *, require_deflection: bool = False) -> TimeSeries:
    """
    Read a rosbag2 bag (directory, ``.mcap`` or ``.db3``) into a :class:`TimeSeries`.

    ``current_topic`` must hold ``Float64MultiArray`` current blocks.
    ``deflection_topic`` (None: ignore) may hold deflection blocks or
    ``PointStamped``; it is aligned to the current sample times and
    ``deflection_alignment`` says how ("exact" or "linear").  If the topic is
    absent the deflection is None, unless ``require_deflection``.
    The geometry comes from ``geometry`` (which must agree with the sidecar's) or else the
    sidecar (see the module docstring); a sidecar, when present, also gives ``known`` and
    ``extra``.
    Every problem raises :class:`DataFormatError` naming the bag and topic.
    """
    bag = Path(path)
    where = str(path)
    if not bag.exists():
        raise DataFormatError(where, None, 'bag not found (no such file or directory)')
    if bag.is_dir():
        if not (bag / 'metadata.yaml').is_file():
            content = sorted(p.name for p in bag.iterdir())[:8]
            raise DataFormatError(where, None, 'not a rosbag2 bag: the directory has no '
                                  f'metadata.yaml (it contains {content})')
    elif bag.suffix not in ('.mcap', '.db3'):
        raise DataFormatError(where, None, 'not a rosbag2 bag: expected a bag directory, a .mcap '
                              'or a .db3 file')
    for member in (bag.iterdir() if bag.is_dir() else [bag]):
        if not (member.is_file() or member.is_dir()):  # a FIFO or device would block the reader
            raise DataFormatError(where, None, f'{member.name} is not a regular file (FIFO or '
                                  'device?): refusing to read it')
    try:
        from rosbags.rosbag2 import Reader
    except ImportError as exc:  # pragma: no cover - rosbags is a workbench dependency
        raise ImportError("reading bags needs the 'rosbags' package "
                          "(pip install 'ipmc_sensor_ros[workbench]')") from exc

    reading: str | None = None
    try:
        with Reader(bag) as reader:
            topics = reader.topics
            found = find_topic(where, topics, current_topic)
            if found is None:
                raise DataFormatError(where, None, f'current topic not found; '
                                      f'{describe_topics(topics)}', topic=current_topic)
            cur_name, cur_info = found
            dfound = None
            if deflection_topic is not None:
                dfound = find_topic(where, topics, deflection_topic)
                if dfound is None and require_deflection:
                    raise DataFormatError(where, None, f'deflection topic not found; '
                                          f'{describe_topics(topics)}', topic=deflection_topic)
            reading = cur_name
            tc, current = read_topic(where, reader, cur_name, cur_info, CURRENT_LABEL, 'current')
            if tc.size < 2:
                raise DataFormatError(where, None, f'only {tc.size} current sample(s); at least 2 '
                                      'are needed', topic=cur_name)
            deflection = alignment = None
            if dfound is not None:
                reading = dfound[0]
                td, vd = read_topic(where, reader, dfound[0], dfound[1], DEFLECTION_LABEL,
                                    'deflection')
                deflection, alignment = align_deflection(where, dfound[0], tc, td, vd)
            reading = None
    except DataFormatError:
        raise
    except Exception as exc:  # rosbags/sqlite3/mcap raise many types on corrupt input
        raise DataFormatError(where, None, f'cannot read bag (corrupt or truncated?): '
                              f'{type(exc).__name__}: {exc}', topic=reading) from exc

    known: dict[str, float] = {}
    extra: dict[str, Any] = {}
    sidecar_path = Path(sidecar) if sidecar is not None else \
        (bag if bag.is_dir() else bag.parent) / SIDECAR_NAME
    if sidecar is not None or sidecar_path.is_file():
        side_geometry, known, extra = _read_sidecar(where, sidecar_path, geometry is None)
        if geometry is None:
            geometry = side_geometry
        elif side_geometry is not None:
            same_geometry(str(sidecar_path), side_geometry, geometry)
            if side_geometry.name and not getattr(geometry, 'name', ''):
                geometry = geometry.replace(name=side_geometry.name)   # the sample's name
    if geometry is None:
        raise DataFormatError(where, None, 'no geometry: give it (ipmc-model: --geometry '
                              'L,W,T, e.g. 22mm,7mm,360um; Python: geometry=) or put an '
                              f"{SIDECAR_NAME} sidecar with 'geometry: {{length_m, width_m, "
                              "thickness_m}' (metres) next to the bag")
    if not isinstance(geometry, Geometry):
        try:
            geometry = Geometry.from_dict(dict(geometry))
        except (ParameterError, TypeError) as exc:
            raise DataFormatError(where, None, f'geometry argument: {exc}') from None
    rate = measured_rate_hz(tc)
    return TimeSeries(path=where, sample=geometry.name, geometry=geometry, known=known,
                      sample_rate_hz=rate, time_s=tc, current_a=current, deflection_m=deflection,
                      extra=extra, deflection_alignment=alignment)


def _stamp_ns(t: float) -> int:
    return int(round(float(t) * 1e9))


def write_bag(path: PathLike, timeseries: TimeSeries, storage: str = 'sqlite3',
              current_topic: str = 'current', deflection_topic: str = 'deflection_truth',
              block_size: int = 100, *, deflection_msgtype: str = MULTIARRAY_TYPE,
              sidecar: bool = True) -> None:
    """
    Write ``timeseries`` as a rosbag2 bag (format version 8) readable by :func:`read_bag`.

    Current (and deflection, if any) go out as ``Float64MultiArray`` blocks of
    up to ``block_size`` samples, each stamped with its last sample time;
    ``deflection_msgtype=POINT_STAMPED_TYPE`` writes one ``PointStamped`` per
    deflection sample instead.  Topic names get a leading '/'.  With
    ``sidecar`` the geometry, known values and extra go to ``<bag>/ipmc.yaml``.
    Sample times must be >= 0 (they become bag timestamps).
    """
    from rosbags.rosbag2 import StoragePlugin

    plugins = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
    if storage not in plugins:
        raise ParameterError(f"storage must be 'sqlite3' or 'mcap', got {storage!r}")
    if int(block_size) != block_size or block_size < 1:
        raise ParameterError(f'block_size must be a positive integer, got {block_size!r}')
    if deflection_msgtype not in (MULTIARRAY_TYPE, POINT_STAMPED_TYPE):
        raise ParameterError(f'deflection_msgtype must be {MULTIARRAY_TYPE!r} or '
                             f'{POINT_STAMPED_TYPE!r}, got {deflection_msgtype!r}')
    ts = timeseries
    if ts.n_samples and not (ts.time_s.min() >= 0.0 and ts.time_s.max() < 2.0 ** 31):
        raise DataFormatError(path, None, f'sample times must be >= 0 and < 2^31 s to be bag '
                              f'timestamps, got {ts.time_s.min():.6g}..{ts.time_s.max():.6g} s: '
                              'write a time series or shift the time origin')
    bag = Path(path)
    if bag.exists():
        raise FileExistsError(f'{bag} exists; write_bag does not overwrite')
    try:
        _write_bag(bag, ts, plugins[storage], current_topic, deflection_topic, block_size,
                   deflection_msgtype, sidecar)
    except BaseException:
        shutil.rmtree(bag, ignore_errors=True)      # never leave a half-written bag
        raise


def _write_bag(bag: Path, ts: TimeSeries, plugin, current_topic: str, deflection_topic: str,
               block_size: int, deflection_msgtype: str, sidecar: bool) -> None:
    import yaml
    from rosbags.rosbag2 import Writer

    store = bag_typestore()
    types = store.types
    F64, Layout, Dim = (types['std_msgs/msg/Float64MultiArray'],
                        types['std_msgs/msg/MultiArrayLayout'],
                        types['std_msgs/msg/MultiArrayDimension'])

    def block(t: np.ndarray, v: np.ndarray, label: str):
        n = int(t.size)
        data = np.empty(2 * n)
        data[0::2], data[1::2] = t, v
        layout = Layout(dim=[Dim(label=SAMPLE_LABEL, size=n, stride=2 * n),
                             Dim(label=label, size=2, stride=2)], data_offset=0)
        return store.serialize_cdr(F64(layout=layout, data=data), MULTIARRAY_TYPE)

    def topic(name: str) -> str:
        return '/' + topic_key(name)

    with Writer(bag, version=8, storage_plugin=plugin) as writer:
        cur = writer.add_connection(topic(current_topic), MULTIARRAY_TYPE, typestore=store)
        dconn = None
        if ts.deflection_m is not None:
            dconn = writer.add_connection(topic(deflection_topic), deflection_msgtype,
                                          typestore=store)
        for start in range(0, ts.n_samples, int(block_size)):
            sl = slice(start, start + int(block_size))
            t = ts.time_s[sl]
            stamp = _stamp_ns(t[-1])
            writer.write(cur, stamp, block(t, ts.current_a[sl], CURRENT_LABEL))
            if dconn is not None and deflection_msgtype == MULTIARRAY_TYPE:
                writer.write(dconn, stamp, block(t, ts.deflection_m[sl], DEFLECTION_LABEL))
        if dconn is not None and deflection_msgtype == POINT_STAMPED_TYPE:
            Point, PointStamped = types['geometry_msgs/msg/Point'], types[POINT_STAMPED_TYPE]
            Header, Time = types['std_msgs/msg/Header'], types['builtin_interfaces/msg/Time']
            for t, d in zip(ts.time_s.tolist(), ts.deflection_m.tolist()):
                ns = _stamp_ns(t)
                sec, nsec = divmod(ns, 10**9)
                # the estimator node's convention: (L, 0, w) in the clamp frame
                msg = PointStamped(header=Header(stamp=Time(sec=sec, nanosec=nsec),
                                                 frame_id='ipmc_clamp'),
                                   point=Point(x=float(ts.geometry.length_m), y=0.0, z=d))
                writer.write(dconn, ns, store.serialize_cdr(msg, POINT_STAMPED_TYPE))
    if sidecar:
        geometry = ts.geometry.to_dict()
        geometry['name'] = ts.sample or ts.geometry.name
        doc: dict[str, Any] = {'geometry': geometry}
        if ts.known:
            doc['material'] = dict(ts.known)
        if ts.extra:
            doc['extra'] = dict(ts.extra)
        (bag / SIDECAR_NAME).write_text(yaml.safe_dump(doc, sort_keys=False), encoding='utf-8')
