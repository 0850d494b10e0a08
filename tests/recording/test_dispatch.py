"""workbench.recording.dispatch.StageDispatch: stage type -> handler, unknown stages are errors."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from workbench.recording.dispatch import StageDispatch


@dataclass
class Telemetry:
    n: int


@dataclass
class Filtered:
    name: str


class Smoothed(Filtered):
    pass


@dataclass
class Final:
    pass


class Unknown:
    pass


def test_dispatch_calls_the_handler_of_the_stage_type():
    seen = []
    d = StageDispatch({Telemetry: lambda s: seen.append(("tel", s.n)), Filtered: lambda s: seen.append(("f", s.name))})
    d(Telemetry(3))
    d(Filtered("forward"))
    assert seen == [("tel", 3), ("f", "forward")]
    assert d.types == (Telemetry, Filtered)


def test_unknown_stage_is_a_type_error_naming_the_type():
    d = StageDispatch({Telemetry: lambda s: None})
    with pytest.raises(TypeError, match=r"test_dispatch\.Unknown") as e:
        d(Unknown())
    assert "Telemetry" in str(e.value)  # the message lists what is registered
    with pytest.raises(TypeError, match="int"):
        d(3)
    with pytest.raises(TypeError, match="none"):
        StageDispatch()(Telemetry(1))


def test_ignored_stages_are_accepted_and_do_nothing():
    seen = []
    d = StageDispatch({Telemetry: seen.append}, ignored=(Final,))
    d(Final())
    d(Telemetry(1))
    assert seen == [Telemetry(1)]
    assert Final in d.types


def test_subclass_goes_to_the_nearest_registered_base():
    seen = []
    d = StageDispatch({Filtered: lambda s: seen.append("base")})
    d(Smoothed("smoothed"))
    d.register(Smoothed, lambda s: seen.append("sub"))
    d(Smoothed("smoothed"))
    d(Filtered("forward"))
    assert seen == ["base", "sub", "base"]


def test_registration_errors():
    d = StageDispatch({Telemetry: lambda s: None})
    with pytest.raises(ValueError, match="already registered"):
        d.register(Telemetry, lambda s: None)
    with pytest.raises(ValueError, match="already registered"):
        d.ignore(Telemetry)
    with pytest.raises(TypeError, match="classes"):
        d.register("Telemetry", lambda s: None)  # a class name is not a type
    with pytest.raises(TypeError, match="callable"):
        d.register(Final, None)


def test_recorders_register_every_stage_their_pipeline_yields():
    """Each stage type the pipelines yield has a handler (or is explicitly ignored) in its recorder."""
    from workbench.problems.droptest import pipeline as dt
    from workbench.problems.droptest.recording import DropTestRecorder
    from workbench.problems.entry import pipeline as en
    from workbench.problems.entry.atmosphere import AtmosphereResult
    from workbench.problems.entry.dispersion import DispersionResult
    from workbench.problems.entry.filter import EntryFilterResult
    from workbench.problems.entry.initial import SmootherStart
    from workbench.problems.entry.preprocess import PreprocessedIMU
    from workbench.problems.entry.recording import EntryRecorder
    from workbench.problems.entry.telemetry import EntryTelemetry
    from workbench.problems.entry.winds import WindResult

    drop = DropTestRecorder(rec=None)
    assert set(drop.dispatch.types) == {
        dt.DropTelemetry,
        dt.InitialState,
        dt.FilterStage,
        dt.StrokeStage,
        dt.DropResult,
    }
    with pytest.raises(TypeError, match="Unknown"):
        drop.handle(Unknown())
    entry = EntryRecorder(None, None, r_ground=0.0, jd_tdb0=0.0, body=None)
    assert set(entry.dispatch.types) == {
        EntryTelemetry,
        PreprocessedIMU,
        en.NominalIntegration,
        DispersionResult,
        SmootherStart,
        EntryFilterResult,
        AtmosphereResult,
        WindResult,
        en.EntryResult,
    }
    with pytest.raises(TypeError, match="Unknown"):
        entry.handle(Unknown())
