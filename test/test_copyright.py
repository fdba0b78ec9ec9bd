# SPDX-License-Identifier: Apache-2.0
"""
Every Python source carries an ``SPDX-License-Identifier: Apache-2.0`` header line.

ament_copyright is not on PyPI; this is the same check for SPDX headers.
"""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _sources():
    for folder in ('ipmc_sensor_ros', 'test', 'launch', 'scripts', 'bench'):
        yield from sorted((ROOT / folder).rglob('*.py'))
    yield ROOT / 'setup.py'


def _has_spdx(path: Path) -> bool:
    head = path.read_text(encoding='utf-8').splitlines()[:3]
    return any('SPDX-License-Identifier: Apache-2.0' in line for line in head)


def test_license_file_is_apache_2():
    text = (ROOT / 'LICENSE').read_text()
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text
    assert '<license>Apache-2.0</license>' in (ROOT / 'package.xml').read_text()


@pytest.mark.linter
def test_spdx_headers():
    missing = [str(p.relative_to(ROOT)) for p in _sources() if not _has_spdx(p)]
    assert not missing, f'{len(missing)} files without an SPDX header: {missing[:20]}'
