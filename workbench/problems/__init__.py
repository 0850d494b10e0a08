"""Reconstruction problems: one package per scenario ``kind`` (``droptest``, ``entry``), the
:class:`~workbench.problems.base.Problem` protocol they implement, the kind -> problem
:mod:`~workbench.problems.registry` and the generic :mod:`~workbench.problems.runner`.

Importing this package imports no problem: the registry loads a built-in one when first asked.
"""
