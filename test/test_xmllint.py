# SPDX-License-Identifier: Apache-2.0
"""
package.xml against the essentials of the package format 3 schema (ament_xmllint is not on PyPI).

And every import of the ROS packages declared as a dependency.
"""
import re
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORDER = ('name', 'version', 'description', 'maintainer', 'license')


def test_package_xml_format_3():
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.tag == 'package' and root.get('format') == '3'
    tags = [c.tag for c in root]
    # the schema's sequence: name, version, description, maintainer+, license+ come first
    assert [t for t in tags if t in ORDER][:5] == list(ORDER)
    assert root.findtext('name') == 'ipmc_sensor_ros'
    assert re.fullmatch(r'\d+\.\d+\.\d+', root.findtext('version'))
    assert root.find('maintainer').get('email')
    assert root.find('export/build_type').text == 'ament_python'
    version = re.search(r'version="([\d.]+)"', (ROOT / 'setup.py').read_text()).group(1)
    assert version == root.findtext('version')


def test_every_ros_import_is_declared():
    root = ET.parse(ROOT / 'package.xml').getroot()
    declared = {e.text for e in root if e.tag.endswith('depend')}
    ros_pkgs = ('rclpy', 'rcl_interfaces', 'std_msgs', 'geometry_msgs', 'rosgraph_msgs',
                'diagnostic_msgs', 'lifecycle_msgs', 'ament_index_python')
    used = set()
    for path in (ROOT / 'ipmc_sensor_ros').rglob('*.py'):
        for m in re.finditer(r'^\s*(?:from|import) (\w+)', path.read_text(), re.M):
            if m.group(1) in ros_pkgs:
                used.add(m.group(1))
    assert used and used <= declared, sorted(used - declared)
