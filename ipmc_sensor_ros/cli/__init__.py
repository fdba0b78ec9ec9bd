"""The ``ipmc-model`` command line (:mod:`.main` holds the parser and the verbs)."""
from .main import main

__all__ = ["main"]
