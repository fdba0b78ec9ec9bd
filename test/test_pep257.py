# SPDX-License-Identifier: Apache-2.0
"""ament_pep257 over the package (``linter`` marker: see test_flake8.py)."""
import pytest


@pytest.mark.linter
def test_pep257():
    main = pytest.importorskip('ament_pep257.main').main
    assert main(argv=['.', 'test']) == 0, 'docstring style findings (see output above)'
