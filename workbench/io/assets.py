"""Where the shipped assets live: landers, entry vehicles and scenarios.

The repository's top-level ``assets/`` folder is installed as the package ``workbench.assets``
(``pyproject.toml``), so the same code finds it in a source checkout, an editable install, a
wheel or a non-editable install, from any working directory.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def assets_dir() -> Path:
    """The shipped assets folder (contains ``landers/``, ``vehicles/``, ``scenarios/``).

    Returns a real directory on disk; raises ``FileNotFoundError`` if the installation ships no
    assets (a broken install), rather than letting a caller find "no scenarios" silently.
    """
    root = Path(str(resources.files("workbench.assets")))
    if not (root / "scenarios").is_dir():
        raise FileNotFoundError(f"the workbench installation has no shipped assets under {root}")
    return root


def asset_path(*parts: str) -> Path:
    """Path of one shipped asset, e.g. ``asset_path("vehicles", "schiaparelli.toml")``."""
    p = assets_dir().joinpath(*parts)
    if not p.is_file():
        raise FileNotFoundError(f"no shipped asset {'/'.join(parts)} (looked in {assets_dir()})")
    return p
