"""The workbench's numba kernels: their decorator, and which of a module's still have to be compiled.

numba's ``cache=True`` writes each compiled kernel beside its source (``__pycache__``, or under
``NUMBA_CACHE_DIR``) as an index file keyed by the source file's time stamp and size, so the first
run of a fresh checkout (or the first after an edit) compiles, later runs load. Compiling leaves
LLVM's memory resident in the process for the rest of its life (about 115 MB for the drop test's
truth and filter kernels, measured), which is why :mod:`workbench.problems.precompile` compiles in a
short child process when :func:`cold_kernels` names any.

:func:`njit` is the decorator of every workbench kernel: numba's ``njit`` with one set of options
for all of them (:data:`KERNEL_OPTIONS`). numba compiles its own implementations (``np.empty``,
``@``, ``np.eye`` ...) once per set of options of the kernel typing them, so kernels with mixed
options compile those twice in one process; and no kernel is passed as a first-class function, so
none needs the C-callable wrapper numba otherwise compiles beside each (its argument unboxing is
as large as the kernel's signature). Division is IEEE's (``error_model="numpy"``): a division by
zero gives ±inf or NaN, as in the numpy reference paths, not a ``ZeroDivisionError``.

The check reads numba's own cache index (``Dispatcher._cache._cache_file._load_index``, numba
0.5x-0.6x); if that internal API is missing, every kernel counts as warm (nothing is precompiled and
the process compiles in place, as before).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from types import ModuleType
from typing import Any

import numba

__all__ = ["KERNEL_OPTIONS", "cold_kernels", "cold_modules", "load_compiler", "njit"]

KERNEL_OPTIONS: dict[str, Any] = {"cache": True, "error_model": "numpy", "no_cfunc_wrapper": True}
"""numba options of every workbench kernel (:func:`njit`): cached on disk, IEEE division, no
C-callable (``cfunc``) wrapper."""


def njit(fn: Callable | None = None, /, **options: Any) -> Any:
    """``numba.njit`` with :data:`KERNEL_OPTIONS` (``options`` add to or override them, e.g.
    ``nogil=True``); used bare (``@njit``) or called (``@njit(nogil=True)``). Returns numba's
    dispatcher (or the decorator making one)."""
    decorator = numba.njit(**{**KERNEL_OPTIONS, **options})
    return decorator if fn is None else decorator(fn)


def load_compiler() -> None:
    """Load numba's typing and lowering registries into this process now: numba does it at the
    first compile or first load from the cache of each process (~0.2 s of CPU), so a process that
    forks several (the scenario processes of ``run all``, the precompiling child) calls this before
    its forks and each child inherits them. If numba's internal ``cpu_target`` is missing, nothing
    is loaded (each child loads its own, as before)."""
    try:
        from numba.core.registry import cpu_target
    except ImportError:  # another numba's internals
        return
    cpu_target.typing_context.refresh()
    cpu_target.target_context.refresh()


def _dispatchers(mod: ModuleType) -> Iterable[tuple[str, object]]:
    """(name, dispatcher) of every cached numba kernel defined at module level in the module ``mod``."""
    module_name = mod.__name__
    for name, obj in sorted(vars(mod).items()):
        cache = getattr(obj, "_cache", None)
        if cache is not None and hasattr(obj, "py_func") and getattr(obj.py_func, "__module__", None) == module_name:
            yield name, obj


def cold_kernels(modules: Iterable[ModuleType]) -> list[str]:
    """``"module.function"`` of each cached numba kernel (:func:`njit`, or ``numba.njit(cache=True)``)
    in ``modules`` that has no compiled version on disk for its current source: the kernels the next
    call would compile.

    ``modules``: imported modules (the caller imports them by name:
    :func:`workbench.problems.registry.import_modules`). Kernels without ``cache=True`` are not
    listed (they compile in every process). An empty list means every kernel loads from the cache,
    or that numba's cache index could not be read (see the module docstring)."""
    cold = []
    for mod in modules:
        for name, disp in _dispatchers(mod):
            try:
                index = disp._cache._cache_file._load_index()
            except (AttributeError, TypeError, OSError):  # another numba's internals: assume warm
                continue
            if not index:
                cold.append(f"{mod.__name__}.{name}")
    return cold


def cold_modules(modules: Iterable[ModuleType]) -> list[str]:
    """The names of the modules in ``modules`` none of whose cached numba kernels has a compiled version on disk:
    a fresh checkout, a cleared cache, or an edit of that module (numba keys its cache on the
    source file's time stamp and size, so an edit makes every kernel of the module cold at once).

    A module with some kernels warm is not listed: a kernel that a scenario never calls stays cold
    for ever and must not make every run precompile. Modules without cached kernels are not listed."""
    out = []
    for mod in modules:
        names = [name for name, _ in _dispatchers(mod)]
        cold = cold_kernels([mod])
        if names and len(cold) == len(names):
            out.append(mod.__name__)
    return out
