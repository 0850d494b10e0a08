"""The worked example problem (``tests/problems/example_fallingbody``) registered for a test.

Several tests run the falling-body example through the command line; this is the one place that
loads its module from file and registers its problem (and undoes both afterwards)."""

from __future__ import annotations

import contextlib
import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

from workbench.problems import registry

EXAMPLE = Path(__file__).resolve().parents[1] / "problems" / "example_fallingbody"
"""Folder of the example: ``fallingbody.py`` (the problem) and ``fallingbody.toml`` (its scenario)."""


@contextlib.contextmanager
def registered_fallingbody(module_name: str = "example_fallingbody", replace: bool = True) -> Iterator[ModuleType]:
    """Load ``fallingbody.py`` as ``module_name``, register its ``FallingBodyProblem`` for the block
    and yield the module; unregister it and forget the module afterwards."""
    spec = importlib.util.spec_from_file_location(module_name, EXAMPLE / "fallingbody.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        p = registry.register(module.FallingBodyProblem(), replace=replace)
        try:
            yield module
        finally:
            registry.unregister(p.kind)
    finally:
        sys.modules.pop(spec.name, None)
