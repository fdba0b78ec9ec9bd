# SPDX-License-Identifier: Apache-2.0
"""
ament_flake8 (line length 99) over the package, as `ros2 pkg create` tests carry it.

Marked ``linter``: runs with the default selection; ``pytest -m linter`` runs the linters
alone.  ``python scripts/lint_fix.py`` fixes what it can (quotes, SPDX headers, docstring
layout) and lists what needs a human.
"""
import pytest


@pytest.mark.linter
def test_flake8():
    from ament_flake8.main import main_with_errors   # installed by the test setup: never skip
    rc, errors = main_with_errors(argv=['--linelength', '99'])
    assert rc == 0, f'{len(errors)} flake8 findings:\n' + '\n'.join(errors[:50])
