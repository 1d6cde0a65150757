"""Load a script of this checkout that is not part of the package (bench/*.py, scripts/*.py) as a
module, so tests can check its functions against known answers."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def load_script(relative: str) -> ModuleType:
    """The module of ``ROOT / relative`` (e.g. ``"bench/pitch_views.py"``), executed once per call, with
    its folder on ``sys.path`` as when it runs as a script (``from figures import write_figure``)."""
    path = ROOT / relative
    if str(path.parent) not in sys.path:
        sys.path.append(str(path.parent))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
