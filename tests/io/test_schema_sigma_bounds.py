"""Every key that declares a 1σ or a noise is bounded below in its schema, whatever its name (fast).

A 1σ of zero or below was accepted for keys whose name does not say "sigma" (the entry
reconstruction's initial and rate 1σ, its IMU datasheet, its dispersion): a negative one ran with its
sign lost or ended in numpy's traceback. The bound lives in the schema, so the error names the file
and key, and FORMATS.md shows it.
"""

from __future__ import annotations

import re

import pytest

from workbench.problems import registry

_NAMED = re.compile(r"sigma|noise")
#: a meaning that says 1σ, in either spelling
_SAYS = re.compile(r"1σ|1-sigma")
_NUMERIC = ("float", "int", "vec3", "list", "number_or_vec3", "number_or_list")


def _declared_1sigma():
    """(schema, table, key) of every numeric key named as a noise or 1σ, or whose meaning or table says 1σ."""
    out = []
    for sch in registry.schemas():
        for t in sch.tables:
            for k in t.keys:
                if k.kind in _NUMERIC and (_NAMED.search(k.name) or _SAYS.search(k.meaning) or _SAYS.search(t.meaning)):
                    out.append((sch, t, k))
    return out


def test_there_are_declared_sigmas_under_other_names():
    """The scan sees the keys this test is about (else it would pass on nothing)."""
    names = {(s.name, t.name, k.name) for s, t, k in _declared_1sigma()}
    assert ("entry", "reconstruction", "rate_dps") in names
    assert ("entry", "dispersion", "attitude_deg") in names
    assert ("meads", "estimator", "model_error_frac") in names  # "1-sigma"
    assert len(names) > 50


@pytest.mark.parametrize("sch, table, key", _declared_1sigma(), ids=lambda x: getattr(x, "name", None) or None)
def test_every_declared_1sigma_is_bounded_below_by_zero(sch, table, key):
    lower = [b for b in (key.ge, key.gt) if b is not None]
    assert lower, f"{sch.name} [{table.name}] {key.name} ({key.meaning!r}) declares a 1σ but has no lower bound"
    assert min(lower) >= 0.0


def test_free_form_sigma_tables_are_bounded():
    """A free-form table of 1σ numbers (a radar gun's range and rate 1σ) bounds every value; a free
    table of sub-tables (post2's ``[states.<name>]``) checks its ``sigma`` and ``psd`` in its own code."""
    seen = 0
    for sch in registry.schemas():
        for t in sch.tables:
            if t.free in _NUMERIC and (
                _SAYS.search(t.free_meaning) or _SAYS.search(t.meaning) or _NAMED.search(t.name)
            ):
                seen += 1
                assert t.free_ge is not None or t.free_gt is not None, f"{sch.name} [{t.name}]"
                assert min(b for b in (t.free_ge, t.free_gt) if b is not None) >= 0.0
    assert seen >= 1
