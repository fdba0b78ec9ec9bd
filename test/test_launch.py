# SPDX-License-Identifier: Apache-2.0
"""Launch files: run them with launch_ros when importable, else check every name they use."""
import ast
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / 'launch'


def _entry_points():
    text = (ROOT / 'setup.py').read_text()
    return set(re.findall(r'[\'"](\w[\w-]*) = ipmc_sensor_ros', text))


def test_launch_files_are_installed():
    text = (ROOT / 'setup.py').read_text()
    text = text.replace('"', "'")   # whatever quote style setup.py is written in
    assert "'/launch'" in text and "glob('launch/*.launch.py')" in text \
        and "glob('launch/*.launch.xml')" in text


def test_python_launch_names_existing_executables_and_files():
    tree = ast.parse((LAUNCH / 'ipmc_pipeline.launch.py').read_text())
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
             and getattr(n.func, 'id', '') == 'Node']
    assert len(calls) == 2
    executables = {kw.value.value for c in calls for kw in c.keywords if kw.arg == 'executable'}
    assert executables == {'ipmc_simulator', 'ipmc_estimator'} <= _entry_points()
    for name in re.findall(
        r"'config', '([\w.]+)'", (LAUNCH / 'ipmc_pipeline.launch.py').read_text()
    ):
        assert (ROOT / 'config' / name).is_file(), name


def test_xml_launch_matches_python_launch():
    root = ET.parse(LAUNCH / 'ipmc_pipeline.launch.xml').getroot()
    args = {a.get('name') for a in root.iter('arg')}
    py = (LAUNCH / 'ipmc_pipeline.launch.py').read_text()
    assert args == set(re.findall(r"DeclareLaunchArgument\('(\w+)'", py))
    nodes = list(root.iter('node'))
    assert {n.get('exec') for n in nodes} == {'ipmc_simulator', 'ipmc_estimator'}
    for n in nodes:
        assert n.get('pkg') == 'ipmc_sensor_ros'
        assert n.find('param').get('from').startswith('$(var ')
    for default in (a.get('default') for a in root.iter('arg')):
        m = re.search(r'\)/config/([\w.]+)$', default or '')
        if m:
            assert (ROOT / 'config' / m.group(1)).is_file()


def test_python_launch_description_builds_when_launch_ros_is_available():
    pytest.importorskip('launch_ros', reason='launch_ros is not on PyPI here; the static '
                        'checks above cover the names')
    import importlib.util

    spec = importlib.util.spec_from_file_location('pipeline', LAUNCH / 'ipmc_pipeline.launch.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert len(mod.generate_launch_description().entities) == 6
