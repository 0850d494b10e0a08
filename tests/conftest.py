"""Test-suite setup: ``tests/support`` (shared synthetic fixtures such as ``entry_synth``) is
importable by its module name from any test (``import entry_synth``)."""

import sys
from pathlib import Path

SUPPORT = str(Path(__file__).resolve().parent / "support")
if SUPPORT not in sys.path:
    sys.path.insert(0, SUPPORT)
