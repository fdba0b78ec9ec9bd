# SPDX-License-Identifier: Apache-2.0
"""The ``ipmc-model`` command line (:mod:`.main` holds the parser and the verbs)."""
from .main import main

__all__ = ['main']
