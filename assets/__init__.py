"""Shipped assets (landers, entry vehicles, scenarios) as package data of ``workbench.assets``.

This folder is installed as the package ``workbench.assets`` (see ``pyproject.toml``), so a wheel
or a non-editable install finds it through :mod:`importlib.resources`; use
:func:`workbench.io.assets.assets_dir` rather than a path relative to the source tree.
"""
