# SPDX-License-Identifier: Apache-2.0
"""
Material parameters and sample geometry of an IPMC sensor, in SI units.

Reference: Z. Chen, X. Tan, A. Will, C. Ziel, "A dynamic model for ionic
polymer-metal composite sensors", Smart Mater. Struct. 16 (2007) 1477-1488
(below: "the paper").  Defaults are the paper's Table 1 (constants and directly
measured values) and Table 2 (values identified by curve fitting); the three
sample geometries are its Table 3.

Material parameters and geometry are kept apart on purpose: one parameter set
describes a sheet of material and serves every sample cut from it, which is the
paper's "geometric scalability" claim (section 5.3.2).

Both classes are frozen dataclasses, validated at construction: a non-physical
value (zero or negative length, negative resistance, NaN, ...) raises
:class:`ParameterError` naming the parameter and the value.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import reprlib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

from ..errors import ParameterError, did_you_mean

__all__ = [
    'ParameterError',
    'MATERIAL_LIMITS',
    'short_repr',
    'parse_number',
    'read_yaml',
    'MaterialParameters',
    'Geometry',
    'PAPER_PARAMETERS',
    'PAPER_SAMPLES',
    'load_yaml',
    'save_yaml',
]


def short_repr(value: Any, limit: int = 60) -> str:
    """
    ``repr(value)`` cut to ``limit`` characters (with '...' and the full length).

    So an error message never echoes a huge value in full (a 10 MB label, an alias-bomb
    YAML). Containers are summarised before ``repr`` expands them.
    """
    if isinstance(value, (list, tuple, dict, set)) and len(value) > 8:
        kind = type(value).__name__
        return f'<{kind} of {len(value)} items>'
    if isinstance(value, (list, tuple, dict, set)):
        try:
            short = reprlib.Repr()           # Python 3.11: no keyword arguments
            short.maxlevel, short.maxstring, short.maxother = 2, limit, limit
            text = short.repr(value)
        except Exception:  # a repr that fails must not hide the error being reported
            text = f'<{type(value).__name__}>'
    else:
        text = repr(value) if not isinstance(value, str) or len(value) <= 4 * limit \
            else repr(value[:limit + 1])
    if len(text) > limit:
        full = len(value) if isinstance(value, str) else len(text)
        text = f'{text[:limit]}... ({full} characters)'
    return text


def _check_keys(cls, data: Any, where: str, what: str, noun: str) -> str:
    """
    Refuse a ``data`` that is not a mapping or has keys ``cls`` does not know.

    Returns the ``"<where>: "`` prefix of messages about it.
    """
    names = {f.name for f in fields(cls)}
    prefix = f'{where}: ' if where else ''
    if not isinstance(data, Mapping):
        raise ParameterError(f'{prefix}{what} must be a mapping of names to values, '
                             f'got {short_repr(data)}')
    unknown = sorted(str(k) for k in set(data) - names)
    if unknown:
        raise ParameterError(f'{prefix}unknown {what} {noun} {short_repr(unknown)}; '
                             f'known: {sorted(names)}' + did_you_mean(unknown, names))
    return prefix


def parse_number(value: Any) -> float:
    """
    ``float(value)``, but a string must be plain ASCII.

    Python's ``float`` also reads Unicode digits ('\u0661\u0662' -> 12.0) and full-width
    forms, which no instrument or file of this project writes (raises ValueError).
    """
    if isinstance(value, bool):
        raise TypeError('a boolean is not a number')
    if isinstance(value, str) and not value.isascii():
        raise ParameterError(f'not an ASCII number: {short_repr(value)}')
    return float(value)


#: Physical range of each material parameter (SI units), checked at construction.  The
#: envelopes are wide (several decades around the paper's Tables 1-2 and the fits'
#: bounds) but keep every derived quantity (K, beta, the reduction) finite: a value
#: like Y = 1e-300 Pa or T = 5e-324 K made the model's linear algebra fail.
#: ``None`` as upper bound = none.
MATERIAL_LIMITS: dict[str, tuple[float, float]] = {
    'faraday_constant_c_per_mol': (9.6e4, 9.7e4),       # a constant (96485.3)
    'gas_constant_j_per_mol_k': (8.3, 8.35),             # a constant (8.3145)
    'temperature_k': (200.0, 400.0),                     # hydrated Nafion: well above freezing
    'youngs_modulus_pa': (1e5, 1e12),                     # soft gels .. stiffer than steel
    'surface_resistance_ohm': (0.0, 1e6),
    'diffusivity_m2_per_s': (1e-20, 1e-6),                # ions in polymers .. liquids 1e-9
    'anion_concentration_mol_per_m3': (1e-2, 1e5),        # water is 5.5e4 mol/m^3
    'permittivity_f_per_m': (8.8e-12, 10.0),              # vacuum .. effective (Table 2: 1.9e-3)
    'charge_stress_coupling_j_per_c': (1e-3, 1e6),
    'one_minus_anion_volume_fraction': (1e-6, 1.0),
}


def _check(name: str, value: Any, *, positive: bool = True, allow_zero: bool = False,
           upper: float | None = None, where: str = '', limits: tuple[float, float] | None = None,
           unit: str = '') -> float:
    """Return ``value`` as float or raise :class:`ParameterError` naming it."""
    prefix = f'{where}: ' if where else ''
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            value = parse_number(value)
        except (TypeError, ValueError, OverflowError):
            raise ParameterError(
                f"{prefix}parameter '{name}' must be a number, got {short_repr(value)}") from None
    value = float(value)
    if not math.isfinite(value):
        raise ParameterError(f"{prefix}parameter '{name}' must be finite, got {value!r}")
    if positive:
        if allow_zero and value < 0.0:
            raise ParameterError(f"{prefix}parameter '{name}' must be >= 0, got {value!r}")
        if not allow_zero and value <= 0.0:
            raise ParameterError(f"{prefix}parameter '{name}' must be > 0, got {value!r}")
    if upper is not None and value > upper:
        raise ParameterError(f"{prefix}parameter '{name}' must be <= {upper}, got {value!r}")
    if limits is not None and not limits[0] <= value <= limits[1]:
        raise ParameterError(f"{prefix}parameter '{name}' = {value!r}{unit} is outside the "
                             f'physical range [{limits[0]:g}, {limits[1]:g}]{unit}')
    return value


@dataclass(frozen=True)
class MaterialParameters:
    """
    Physical parameters of an IPMC material (paper Tables 1-2), SI units.

    Attributes
    ----------
    faraday_constant_c_per_mol : F, C mol^-1 (Table 1: 96487).
    gas_constant_j_per_mol_k : R, J mol^-1 K^-1 (Table 1: 8.3143).
    temperature_k : T, absolute temperature, K (Table 1: 300).
    youngs_modulus_pa : Y, Pa (Table 1: 5.71e8).
    surface_resistance_ohm : r0, surface-electrode resistance per unit length
        and unit width, ohm (Table 1: 6.05).  Only the ``surface_resistance``
        effect (the paper's H2, eq. 45) uses it.
    diffusivity_m2_per_s : d, ionic diffusivity, m^2 s^-1 (Table 2: 3.32e-11).
    anion_concentration_mol_per_m3 : C-, mol m^-3 (Table 2: 1091).
    permittivity_f_per_m : kappa_e, effective dielectric permittivity, F m^-1
        (Table 2: 1.88e-3).
    charge_stress_coupling_j_per_c : alpha0, eq. 16, J C^-1 (Table 2: 104).
    one_minus_anion_volume_fraction : 1 - C- dV, dimensionless (paper section
        5.2 takes it as 1 since |C- dV| << 1).

    """

    faraday_constant_c_per_mol: float = 96487.0
    gas_constant_j_per_mol_k: float = 8.3143
    temperature_k: float = 300.0
    youngs_modulus_pa: float = 5.71e8
    surface_resistance_ohm: float = 6.05
    diffusivity_m2_per_s: float = 3.32e-11
    anion_concentration_mol_per_m3: float = 1091.0
    permittivity_f_per_m: float = 1.88e-3
    charge_stress_coupling_j_per_c: float = 104.0
    one_minus_anion_volume_fraction: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            allow_zero = f.name == 'surface_resistance_ohm'
            object.__setattr__(self, f.name, _check(f.name, getattr(self, f.name),
                                                    allow_zero=allow_zero,
                                                    limits=MATERIAL_LIMITS[f.name]))

    # -- derived quantities -------------------------------------------------
    @property
    def k_rate_per_s(self) -> float:
        """K = F^2 d C- (1 - C- dV) / (kappa_e R T), s^-1 (paper, definition after eq. 12)."""
        return (self.faraday_constant_c_per_mol ** 2 * self.diffusivity_m2_per_s
                * self.anion_concentration_mol_per_m3 * self.one_minus_anion_volume_fraction
                / (self.permittivity_f_per_m * self.gas_constant_j_per_mol_k * self.temperature_k))

    def replace(self, **changes: float) -> 'MaterialParameters':
        """Return a copy with ``changes`` applied (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = '') -> 'MaterialParameters':
        _check_keys(cls, data, where, 'material', 'parameter(s)')
        try:
            return cls(**dict(data))
        except ParameterError as exc:
            if where:
                raise ParameterError(f'{where}: {exc}') from None
            raise


#: Plausible physical ranges of each geometric quantity, used to catch unit
#: mistakes (millimetres given as metres).  A 2 m long IPMC does not exist.
GEOMETRY_LIMITS_M = {
    'length_m': (1e-4, 1.0),
    'width_m': (1e-4, 1.0),
    'thickness_m': (1e-6, 1e-2),
}


@dataclass(frozen=True)
class Geometry:
    """
    Cantilever geometry of one sample (paper Fig. 1, Table 3), metres.

    length_m : L, free (bending) length from the clamp to the tip.
    width_m : W.
    thickness_m : 2h, total thickness; ``half_thickness_m`` is h.
    name : optional label (e.g. ``slim``).
    """

    length_m: float
    width_m: float
    thickness_m: float
    name: str = ''

    def __post_init__(self) -> None:
        for key, (lo, hi) in GEOMETRY_LIMITS_M.items():
            value = _check(key, getattr(self, key), where=self.name)
            if not lo <= value <= hi:
                raise ParameterError(
                    f"{self.name + ': ' if self.name else ''}parameter '{key}' = {value!r} m is "
                    f'outside the physical range [{lo}, {hi}] m (is it in millimetres?)')
            object.__setattr__(self, key, value)

    @property
    def half_thickness_m(self) -> float:
        """h, distance from the neutral axis to the surface (paper Fig. 1)."""
        return 0.5 * self.thickness_m

    def replace(self, **changes: Any) -> 'Geometry':
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return {'length_m': self.length_m, 'width_m': self.width_m,
                'thickness_m': self.thickness_m, 'name': self.name}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = '') -> 'Geometry':
        prefix = _check_keys(cls, data, where, 'geometry', 'key(s)')
        missing = sorted({'length_m', 'width_m', 'thickness_m'} - set(data))
        if missing:
            raise ParameterError(f'{prefix}missing geometry key(s) {missing}')
        try:
            return cls(**dict(data))
        except ParameterError as exc:
            if where:
                raise ParameterError(f'{prefix}{exc}') from None
            raise


#: Paper Tables 1-2.
PAPER_PARAMETERS = MaterialParameters()

#: Paper Table 3: the three samples cut from one sheet.
PAPER_SAMPLES: dict[str, Geometry] = {
    'big': Geometry(22e-3, 14e-3, 360e-6, 'big'),
    'slim': Geometry(22e-3, 7e-3, 360e-6, 'slim'),
    'short': Geometry(11e-3, 7e-3, 360e-6, 'short'),
}


#: Largest parameters / YAML file read, bytes (real ones are a few kB).
MAX_YAML_BYTES = 1_000_000


def read_yaml(path: str | Path, what: str = 'YAML file') -> Any:
    """
    Parse a small YAML file with ``yaml.safe_load``.

    Every failure is one :class:`ParameterError` line naming the file (and the line
    for syntax errors): missing, not a regular file (a FIFO would block), too large,
    not text (UTF-8, or UTF-16 with a byte-order mark, as rcl reads), invalid YAML, a
    ``!!python`` tag.
    """
    import yaml

    path = Path(path)
    try:
        if not path.exists():
            raise ParameterError(f'{path}: {what} not found')
        if not path.is_file():
            raise ParameterError(f'{path}: {what} is not a regular file')
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise ParameterError(f'{path}: {what} is {size} bytes, more than the limit '
                                 f'{MAX_YAML_BYTES} (is it the right file?)')
        raw = path.read_bytes()[:MAX_YAML_BYTES + 1]
    except OSError as exc:
        raise ParameterError(f'{path}: cannot read the {what}: {exc.strerror or exc}') from None
    bom16 = raw[:2] in (b'\xff\xfe', b'\xfe\xff')      # UTF-16 with a byte-order mark
    try:
        text = raw.decode('utf-16' if bom16 else 'utf-8-sig')
    except UnicodeDecodeError as exc:
        raise ParameterError(f'{path}: {what} is not UTF-8 (or UTF-16 with a byte-order mark) '
                             f'text: undecodable byte at offset {exc.start}') from None
    try:
        return yaml.load(text, Loader=_loader())
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        line = f':{mark.line + 1}' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or str(exc)
        problem = ' '.join(str(problem).split())[:200]
        raise ParameterError(f'{path}{line}: not valid YAML for a {what}: {problem}') from None
    except RecursionError:
        raise ParameterError(f'{path}: {what} is nested too deeply') from None


@functools.cache
def _loader():
    """
    Return ``yaml.SafeLoader`` reading YAML 1.2 floats as numbers, as ROS 2 (rcl) does.

    PyYAML follows YAML 1.1, where ``22e-3`` and ``1.5e3`` (no dot, or no exponent sign) are
    strings: a params file the node reads would be refused here.
    """
    import re

    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_implicit_resolver('tag:yaml.org,2002:float', re.compile(
        r'^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$'), list('-+0123456789.'))
    return Loader


def load_yaml(path: str | Path) -> tuple[MaterialParameters, Geometry | None]:
    """
    Load ``material:`` (and optional ``geometry:``) from a YAML file.

    Missing material keys take the paper's defaults.  Errors name the file.
    """
    path = Path(path)
    data = read_yaml(path, 'parameters file') or {}
    if not isinstance(data, dict):
        raise ParameterError(f"{path}: expected a mapping with 'material' and 'geometry' keys")
    unknown = sorted(set(data) - {'material', 'geometry', 'model'})
    if unknown:
        raise ParameterError(f'{path}: unknown top-level key(s) {short_repr(unknown)}; '
                             "known: ['geometry', 'material', 'model']")
    material = MaterialParameters.from_dict(data.get('material') or {}, where=str(path))
    geometry = None
    if data.get('geometry') is not None:
        geometry = Geometry.from_dict(data['geometry'], where=str(path))
    return material, geometry


def save_yaml(path: str | Path, material: MaterialParameters,
              geometry: Geometry | None = None, extra: Mapping[str, Any] | None = None) -> None:
    """Write ``material`` (and ``geometry``) as YAML readable by :func:`load_yaml`."""
    import yaml

    doc: dict[str, Any] = {'material': material.to_dict()}
    if geometry is not None:
        doc['geometry'] = geometry.to_dict()
    if extra:
        doc.update(extra)
    Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))
