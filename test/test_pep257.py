# SPDX-License-Identifier: Apache-2.0
"""ament_pep257 over the package (``linter`` marker: see test_flake8.py)."""
import pytest


@pytest.mark.linter
def test_pep257():
    from ament_pep257.main import main   # installed by the test setup: never skip
    assert main(argv=['.', 'test']) == 0, 'docstring style findings (see output above)'
