"""workbench.recording.layout against docs/RECORDING.md, and no raw entity paths in the recorders."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import pytest

from workbench.recording import layout

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "RECORDING.md"
RECORDERS = [
    "workbench/problems/droptest/recording.py",
    "workbench/problems/entry/recording.py",
    "workbench/problems/entry/recording_mc.py",
    "workbench/problems/droptest/recording_mc.py",
    "workbench/problems/post2/recording_mc.py",
    "workbench/recording/blueprint.py",
    "workbench/recording/compare.py",
    "workbench/cli.py",
]
TOP = ("world", "plots", "residuals", "sensors", "profiles", "events", "report", "compare")
ROW = re.compile(r"^\|\s*`(/[^`]*)`\s*\|")

# example arguments for each path family (the result must match the family's template)
FAMILY_ARGS = {
    "meads_port_plot_path": ("P1", "measured"),
    "meads_trade_path": ("alpha_deg", "1pct"),
    "meads_truth_mc_path": ("qbar_pct", "ekf_pass2_mc"),
    "post2_truth_mc_path": ("grid_nees", "position_mean"),
    "meads_ekf_plot_path": ("alpha_deg", 2),
    "meads_scale_factor_path": ("pass1",),
    "meads_ekf_innovation_path": (1, "P3"),
    "radar_beam_path": (2,),
    "truth_path": ("vehicle",),
    "plot_path": ("altitude",),
    "residual_path": ("gyro", "x"),
    "sensor_path": ("imu", "ax"),
    "droptest_ranging_sensor_path": ("gun1.range",),
    "droptest_nis_path": ("zupt",),
    "droptest_triad_plot_path": ("BP", layout.MEASURED_SERIES),
    "droptest_sigma_path": ("position", layout.SMOOTHED_SERIES),
    "entry_dispersion_plot_path": ("t_PDD", layout.ACCEPTED),
    "entry_dispersion_at_pdd_path": (layout.REJECTED,),
    "entry_dispersion_tracks_path": (layout.ACCEPTED,),
    "entry_residual_path": ("slant_range", "B0"),
    "entry_radar_plot_path": ("slant_out", layout.PREDICTED_SERIES),
    "entry_wind_plot_path": ("north",),
    "entry_wind_profile_path": ("east", "plus_1sigma"),
    "validation_rms_path": (layout.VALIDATION_RMS_VELOCITY, "vel_N", True),
    "compare_run_path": ("a", "vehicle"),
    "compare_diff_path": ("stroke",),
    "compare_overlay_path": ("stroke", "b"),
    "compare_position_path": ("x",),
}


def _doc_rows() -> list[str]:
    return [m.group(1) for line in DOC.read_text(encoding="utf-8").splitlines() if (m := ROW.match(line))]


def _template_regex(template: str) -> re.Pattern:
    """``/a/<x>[/<y>]`` -> regex: ``<x>`` one part (or more parts for nested names), ``[...]`` optional."""
    out, i = "", 0
    while i < len(template):
        c = template[i]
        if c == "<":
            j = template.index(">", i)
            out += r"[\w.\-]+"
            i = j + 1
        elif c == "[":
            out += "(?:"
            i += 1
        elif c == "]":
            out += ")?"
            i += 1
        else:
            out += re.escape(c)
            i += 1
    return re.compile(out + r"\Z")


def test_constant_paths_are_well_formed_and_unique():
    paths = layout.constant_paths()
    assert len(paths) > 100  # every group is there (generic, DROPTEST, ENTRY, MC, VALIDATION)
    for prefix in ("DROPTEST_", "ENTRY_", "MC_", "VALIDATION_"):
        assert any(k.startswith(prefix) for k in paths), prefix
    for name, p in paths.items():
        assert p.startswith("/") and not p.endswith("/") and "//" not in p, (name, p)
        assert layout.join("/", *p.strip("/").split("/")) == p, (name, p)  # every part passes layout.part
        assert p.split("/")[1] in TOP, (name, p)
    dupes = {p for p in paths.values() if list(paths.values()).count(p) > 1}
    assert not dupes, f"paths defined twice: {dupes}"


def test_every_constant_and_family_is_documented_and_vice_versa():
    rows = _doc_rows()
    assert len(rows) == len(set(rows)), "a path has two rows in docs/RECORDING.md"
    documented = set(rows)
    constants = set(layout.constant_paths().values())
    templates = set(layout.path_families().values())
    assert not constants - documented, f"undocumented constant paths: {sorted(constants - documented)}"
    assert not templates - documented, f"undocumented path families: {sorted(templates - documented)}"
    assert not documented - constants - templates, (
        f"documented paths missing in layout.py: {sorted(documented - constants - templates)}"
    )


def test_timelines_and_leaf_names_are_documented():
    text = DOC.read_text(encoding="utf-8")
    for tl in layout.TIMELINES:
        assert f"| `{tl}` |" in text, tl
    leaves = {k: v for k, v in vars(layout).items() if k.isupper() and isinstance(v, str) and not v.startswith("/")}
    not_leaves = ("APPLICATION_ID", "TIME", "STEP", "ITERATION", "SAMPLE", "MACH_DESCENDING")
    leaves = {k: v for k, v in leaves.items() if k not in not_leaves}
    assert len(leaves) >= 10
    for k, v in leaves.items():
        assert f"| `{v}` | `{k}` |" in text, k


def test_path_families_match_their_templates():
    fams = layout.path_families()
    public = {n for n in layout.__all__ if n.endswith("_path")}
    assert public == set(fams) == set(FAMILY_ARGS)
    for name, template in fams.items():
        fn = getattr(layout, name)
        assert fn.__doc__, name
        out = fn(*FAMILY_ARGS[name])
        assert _template_regex(template).match(out), (name, out, template)
    # optional parts really are optional
    assert layout.residual_path("zupt") == "/residuals/zupt"
    assert layout.residual_path("BP", "x") == "/residuals/BP/x"
    assert layout.sensor_path("gyro") == layout.DROPTEST_SENSOR_GYRO
    assert layout.entry_residual_path("slant_out") == layout.ENTRY_RESIDUAL_SLANT_OUT
    assert layout.entry_wind_profile_path("north") == "/profiles/wind/north"
    assert layout.validation_rms_path(layout.VALIDATION_RMS_ATTITUDE, "att_x") == "/plots/validation/rms/attitude/att_x"


def test_families_reject_bad_parts():
    with pytest.raises(ValueError):
        layout.residual_path("gyro", "a b")
    with pytest.raises(ValueError):
        layout.droptest_nis_path("")
    with pytest.raises(ValueError, match="VALIDATION_RMS"):
        layout.validation_rms_path("/plots/validation/rms/other", "x")


def test_constant_paths_lists_only_paths_in_definition_order():
    names = list(layout.constant_paths())
    assert names[0] == "WORLD"
    assert names.index("DROPTEST_CHAMBER_AXES") < names.index("ENTRY_SITE_AXES") < names.index("MC_ROOT")
    assert "VALUE" not in names and "TIME" not in names and "APPLICATION_ID" not in names


def _raw_paths(source: str) -> list[tuple[int, str]]:
    """String literals (plain or the head of an f-string) that start like an entity path."""
    pat = re.compile(r"^/(" + "|".join(TOP) + r")\b")
    hits = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and pat.match(node.value):
            hits.append((node.lineno, node.value))
        elif isinstance(node, ast.JoinedStr) and node.values:
            head = node.values[0]
            if isinstance(head, ast.Constant) and isinstance(head.value, str) and pat.match(head.value):
                hits.append((node.lineno, head.value))
            elif isinstance(head, ast.FormattedValue) and len(node.values) > 1:
                nxt = node.values[1]  # f"{root}/value": a path assembled by hand
                if isinstance(nxt, ast.Constant) and str(nxt.value).startswith("/"):
                    hits.append((node.lineno, "{…}" + str(nxt.value)))
    return sorted(set(hits))  # an f-string's head is also visited as a plain constant


@pytest.mark.parametrize("rel", RECORDERS)
def test_recorders_spell_no_entity_path(rel):
    hits = _raw_paths((ROOT / rel).read_text(encoding="utf-8"))
    assert not hits, f"{rel}: raw entity paths (use workbench.recording.layout): {hits}"


def test_raw_path_detector_finds_literals():
    src = 'a = "/plots/x"\nb = f"/world/{n}"\nc = f"{root}/value"\nd = "(no /report here)"\n'
    assert [v for _, v in _raw_paths(src)] == ["/plots/x", "/world/", "{…}/value"]  # one hit per literal


def test_layout_and_dispatch_do_not_import_rerun():
    from workbench.recording import dispatch

    for mod in (layout, dispatch):
        tree = ast.parse(inspect.getsource(mod))
        names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
        assert not [m for m in names if m.split(".")[0] == "rerun"], mod.__name__
