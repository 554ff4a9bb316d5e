"""A script or benchmark of the repository (not a package) imported as a module, for the tests that call into it.

census = load_module("scripts/bad_input_census.py")
"""

from __future__ import annotations

import importlib.util
from types import ModuleType

from flownav.paths import REPO_ROOT


def load_module(relative_path: str) -> ModuleType:
    path = REPO_ROOT / relative_path
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
