"""The problem registry: built-in kinds loaded lazily, register/unregister, clear unknown-kind errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from workbench.problems import registry
from workbench.problems.base import Problem


class _Dummy:
    """The smallest object that satisfies the protocol (no behaviour)."""

    kind = "dummy"
    title = "nothing"
    schema = None

    def __getattr__(self, name):
        if name in {m for m in vars(Problem) if not m.startswith("_")}:
            return lambda *a, **k: None
        raise AttributeError(name)


@pytest.fixture
def dummy():
    d = _Dummy()
    yield d
    registry.unregister("dummy")


def test_builtin_kinds_and_protocol():
    assert {"droptest", "entry"} <= set(registry.kinds())
    for kind in ("droptest", "entry"):
        p = registry.get(kind)
        assert isinstance(p, Problem) and p.kind == kind
        assert registry.get(kind) is p  # one instance per kind


def test_importing_the_registry_does_not_import_the_pipelines():
    code = (
        "import sys, workbench.problems, workbench.problems.registry as r; r.kinds(); "
        "print(any(m.startswith(('workbench.problems.droptest', 'workbench.problems.entry')) for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_unknown_kind_names_the_known_ones():
    with pytest.raises(registry.UnknownKindError) as info:
        registry.get("rocket", where="my.toml")
    msg = str(info.value)
    assert msg.startswith("my.toml: ") and "'rocket'" in msg and "known kinds: droptest, entry, meads, post2" in msg
    assert info.value.kind == "rocket"


def test_register_and_unregister(dummy):
    assert registry.register(dummy) is dummy
    assert registry.get("dummy") is dummy and "dummy" in registry.kinds()
    with pytest.raises(ValueError, match="already"):
        registry.register(_Dummy())
    other = registry.register(_Dummy(), replace=True)
    assert registry.get("dummy") is other
    assert registry.unregister("dummy") is other
    assert registry.unregister("dummy") is None
    with pytest.raises(registry.UnknownKindError):
        registry.get("dummy")


def test_builtin_kind_is_not_taken_silently(dummy):
    dummy.kind = "droptest"
    with pytest.raises(ValueError, match="'droptest' already"):
        registry.register(dummy)
    registry.unregister("droptest")  # a built-in comes back on the next get
    assert registry.get("droptest").kind == "droptest"


def test_register_refuses_non_problems():
    class NoKind:
        pass

    class Half:
        kind = "half"

        def reconstruct(self, *a):
            return iter(())

    with pytest.raises(TypeError, match="kind"):
        registry.register(NoKind())
    with pytest.raises(TypeError, match="missing: .*synthesize"):
        registry.register(Half())
    assert "half" not in registry.kinds()
