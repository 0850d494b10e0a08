"""Every documented scenario key is read (issue 12, item 3): a key that ``io/FORMATS.md`` documents
(its tables are generated from the problems' schemas) but the pipeline ignores fails here.

For each problem whose settings are built into one config object (``config_for``: droptest, post2,
meads), every schema key of a number, integer, boolean, vector or choice kind is given another
valid value in a copy of a shipped scenario; the config built from it must differ (the key reaches
the config), and every field of the problem's own config classes that changed must be read
somewhere in ``workbench/`` outside the config module (an attribute access ``.<field>`` in the
problem's own package or the shared code, not another problem's; fields of shared model classes
held in the config, such as ``ImuErrorModel``, are left to those models), so a value copied into
the config and then never used — as ``sensors.accelerometer.scale`` once was — fails.  A changed
value that the problem's own checks refuse (a ``ScenarioError`` naming that key) counts as read.

Not covered, and why: string keys (names, file paths; read when the files are opened) and
free-form list keys (no generic "other valid value"); the entry problem, whose sensor and truth
keys are read by the simulator and the pipeline from the scenario directly, not through one
config object, so this mutation check cannot see them.
"""

from __future__ import annotations

import dataclasses
import importlib
import re
from pathlib import Path

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError, resolve_scenario
from workbench.io.schema import REQUIRED
from workbench.problems import registry

ROOT = Path(__file__).resolve().parents[2]
#: problem config module -> the shipped scenario mutated
PROBLEMS = {
    "workbench.problems.droptest.config": "droptest",
    "workbench.problems.post2.config": "post2_j2",
    "workbench.problems.meads.config": "msl_meads",
}


def _flat(obj, path: str = "", out: dict | None = None, owners: tuple = ()) -> dict[str, tuple]:
    """Leaf values of a config (dataclasses, dicts, sequences, arrays) by path ``a.b[k][0]``, each
    with the (field, module of the dataclass that declares it) pairs along its path."""
    out = {} if out is None else out
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            owner = (f.name, type(obj).__module__)
            _flat(getattr(obj, f.name), f"{path}.{f.name}" if path else f.name, out, (*owners, owner))
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _flat(v, f"{path}[{k}]", out, owners)
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            _flat(v, f"{path}[{i}]", out, owners)
    elif isinstance(obj, np.ndarray):
        out[path] = (tuple(np.ravel(obj).tolist()), owners)
    else:
        out[path] = (repr(obj), owners)
    return out


def _other_value(key, current):
    """Another valid-looking value of ``key`` (a schema Key), or None for kinds not mutated."""
    v = current if current is not None else (None if key.default is None or key.default is REQUIRED else key.default)
    if key.choices:
        return next(c for c in key.choices if c != v)
    if key.kind == "float":
        return 0.5 if v is None else float(v) * 1.1 + 0.01
    if key.kind == "int":
        return 1 if v is None else int(v) + 1
    if key.kind == "bool":
        return True if v is None else not v
    if key.kind in ("vec3", "number_or_vec3"):
        return [0.1, 0.2, 0.3] if v is None else (np.asarray(v, float) * 1.1 + 0.01).tolist()
    return None


@pytest.mark.parametrize("module", list(PROBLEMS))
def test_every_documented_key_is_read(module):
    mod = importlib.import_module(module)
    cfg_file = Path(mod.__file__).resolve()
    problems = ROOT / "workbench" / "problems"
    own = cfg_file.parent

    def readable(p: Path) -> bool:  # this problem's package and the shared code, not other problems'
        p = p.resolve()
        return p != cfg_file and (own in p.parents or not (problems in p.parents and p.parent != problems))

    code = "\n".join(p.read_text() for p in (ROOT / "workbench").rglob("*.py") if readable(p))
    sc = resolve_scenario(PROBLEMS[module], assets_dir())
    build = registry.get(sc.kind).settings  # the run's frozen settings (issue 25)
    base = _flat(build(sc))
    checked, ignored, unused = 0, [], set()
    for table in mod.SCHEMA.tables:
        for key in table.keys:
            dotted = f"{table.name}.{key.name}"
            new = _other_value(key, sc.get(dotted) if sc.has(dotted) else None)
            if new is None:
                continue
            checked += 1
            try:
                cfg = build(sc.with_overrides({dotted: new}))
            except ScenarioError as err:
                assert err.key == dotted, f"{dotted} = {new!r} refused, but for another key: {err}"
                continue
            changed = [owners for p, (v, owners) in _flat(cfg).items() if base.get(p, (None,))[0] != v]
            if not changed:
                ignored.append(dotted)
            for owners in changed:  # fields of the problem's own config classes (shared models read theirs)
                unused.update(f for f, m in owners if m == module and not re.search(rf"\.{f}\b", code))
    assert checked > 10
    assert not ignored, f"{module}: documented keys that do not reach the config: {ignored}"
    assert not unused, f"{module}: config fields set from documented keys but read nowhere: {sorted(unused)}"
