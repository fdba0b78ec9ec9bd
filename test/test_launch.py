# SPDX-License-Identifier: Apache-2.0
"""
Launch files: run them with launch_ros when importable, else check every name they use.

Without launch_ros the Python launch file is executed against recording stand-ins of the
launch API (``launch``, ``launch_ros``, ``ament_index_python``), so what it names is read as
it builds it, plain and managed variant alike; the XML file is parsed.  Every executable must
be an entry point of setup.py, every parameter set in the file a parameter of the node that
executable runs, every file an existing package file; both files offer the same arguments.
"""
import importlib.util
import re
import sys
import types
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ipmc_sensor_ros.nodes.managed import ManagedEstimatorNode, ManagedSimulatorNode
from ipmc_sensor_ros.nodes.estimator_node import ESTIMATOR_SPECS
from ipmc_sensor_ros.nodes.simulator_node import SIMULATOR_SPECS

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / 'launch'
PLAIN = {'ipmc_simulator', 'ipmc_estimator'}
MANAGED = {'ipmc_simulator_managed', 'ipmc_estimator_managed'}
#: parameter names each executable declares (an unknown one stops the node, exit 2)
DECLARED = {
    'ipmc_simulator': {s.name for s in SIMULATOR_SPECS},
    'ipmc_estimator': {s.name for s in ESTIMATOR_SPECS},
    'ipmc_simulator_managed': {s.name for s in ManagedSimulatorNode._SPECS},
    'ipmc_estimator_managed': {s.name for s in ManagedEstimatorNode._SPECS},
}


def _entry_points():
    text = (ROOT / 'setup.py').read_text()
    return set(re.findall(r'[\'"](\w[\w-]*) = ipmc_sensor_ros', text))


class _Recorded:
    """A stand-in launch class: keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


def _stub_modules():
    """Return stand-ins of the launch modules the Python launch file imports."""
    made = {}
    for name in ('launch', 'launch.actions', 'launch.conditions', 'launch.substitutions',
                 'launch_ros', 'launch_ros.actions', 'ament_index_python',
                 'ament_index_python.packages'):
        made[name] = types.ModuleType(name)
    for module, names in (('launch', ['LaunchDescription']),
                          ('launch.actions', ['DeclareLaunchArgument']),
                          ('launch.conditions', ['IfCondition', 'UnlessCondition']),
                          ('launch.substitutions', ['LaunchConfiguration']),
                          ('launch_ros.actions', ['Node'])):
        for name in names:
            setattr(made[module], name, type(name, (_Recorded,), {}))
    made['ament_index_python.packages'].get_package_share_directory = lambda pkg: str(ROOT)
    return made


@pytest.fixture
def python_launch(monkeypatch):
    """Return (arguments {name: DeclareLaunchArgument}, nodes) of the Python launch file."""
    for name, module in _stub_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location('pipeline_stubbed',
                                                  LAUNCH / 'ipmc_pipeline.launch.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    entities = mod.generate_launch_description().args[0]
    args = {e.args[0]: e for e in entities if type(e).__name__ == 'DeclareLaunchArgument'}
    nodes = [e for e in entities if type(e).__name__ == 'Node']
    assert len(args) + len(nodes) == len(entities)
    return args, nodes


def test_launch_files_are_installed():
    text = (ROOT / 'setup.py').read_text()
    text = text.replace('"', "'")   # whatever quote style setup.py is written in
    assert "'/launch'" in text and "glob('launch/*.launch.py')" in text \
        and "glob('launch/*.launch.xml')" in text


def test_python_launch_names_existing_executables_parameters_and_files(python_launch):
    args, nodes = python_launch
    assert args['managed'].kwargs['default_value'] == 'false'
    by_variant = {}
    for node in nodes:
        kw = node.kwargs
        condition = kw['condition']
        # every node is switched by the managed argument, one way or the other
        assert condition.args[0].args == ('managed',)
        managed = type(condition).__name__ == 'IfCondition'
        exe = kw['executable']
        assert kw['package'] == 'ipmc_sensor_ros' and exe in _entry_points()
        by_variant.setdefault(managed, set()).add(exe)
        # node names stay those of the plain nodes (params files key on them)
        assert kw['name'] == exe.replace('_managed', '')
        for entry in kw['parameters']:
            if isinstance(entry, dict):        # parameters set in the launch file itself
                assert set(entry) <= DECLARED[exe], (exe, entry)
            else:                              # a params file: a declared launch argument
                assert entry.args[0] in args
        assert {a.args[0] for _, a in kw['remappings']} <= set(args)
    assert by_variant == {False: PLAIN, True: MANAGED}
    managed_params = [p for n in nodes if n.kwargs['executable'] in MANAGED
                      for p in n.kwargs['parameters'] if isinstance(p, dict)]
    assert managed_params == [{'autostart': True}] * 2   # they activate themselves
    for a in args.values():
        default = a.kwargs['default_value']
        if default.endswith('.yaml'):
            assert Path(default).is_file() and Path(default).parent == ROOT / 'config', default


def test_xml_launch_matches_python_launch(python_launch):
    py_args, py_nodes = python_launch
    root = ET.parse(LAUNCH / 'ipmc_pipeline.launch.xml').getroot()
    args = {a.get('name'): a.get('default') for a in root.iter('arg')}
    assert set(args) == set(py_args)
    for name, default in args.items():       # same defaults (files: same package file)
        py_default = py_args[name].kwargs['default_value']
        if default.startswith('$(find-pkg-share ipmc_sensor_ros)/'):
            path = ROOT / default.split(')/', 1)[1]
            assert path.is_file() and str(path) == py_default, name
        else:
            assert default == py_default, name
    nodes = list(root.iter('node'))
    variants = {}
    for n in nodes:
        assert n.get('pkg') == 'ipmc_sensor_ros' and n.get('exec') in _entry_points()
        assert (n.get('if'), n.get('unless')) in (('$(var managed)', None),
                                                  (None, '$(var managed)'))
        variants.setdefault(n.get('if') is not None, set()).add(n.get('exec'))
        assert n.get('name') == n.get('exec').replace('_managed', '')
        params = n.findall('param')
        assert params[0].get('from').startswith('$(var ')
        named = {p.get('name'): p.get('value') for p in params if p.get('name')}
        assert set(named) <= DECLARED[n.get('exec')], (n.get('exec'), named)
        assert named == ({'autostart': 'true'} if n.get('exec') in MANAGED else {})
    assert variants == {False: PLAIN, True: MANAGED}
    assert len(nodes) == len(py_nodes)


def test_python_launch_description_builds_when_launch_ros_is_available():
    pytest.importorskip('launch_ros', reason='launch_ros is not on PyPI here; the checks '
                        'above run the file against stand-ins of the launch API')
    spec = importlib.util.spec_from_file_location('pipeline', LAUNCH / 'ipmc_pipeline.launch.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert len(mod.generate_launch_description().entities) == 9   # 5 arguments, 4 nodes
