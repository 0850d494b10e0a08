"""The README's recording images, from the current code: each problem's main scenario run, its
layout opened at a key moment and shot in Rerun's web viewer, with the numbers of the captions
taken from the same run.

For each of :data:`SHOTS` (scenario, key moment, image name): ``workbench run`` (all four in one
call, into a temporary folder), the moment's layout (``workbench open --at`` without a viewer:
:func:`workbench.recording.moments.write_moment_blueprint`), a screenshot of the recording with that
layout at the moment's time (:func:`workbench.recording.browser.check_recordings`, 1600×1000), the
PNG copied to ``--out`` and the run's caption numbers (the headline, the health verdict, the
moment's time) written to ``--json`` — which the README's ``images`` block is rendered from
(``make_results.py``), so a caption cannot disagree with its picture.  Exit 1 when the viewer
reported an error or a 3D view was empty.  Needs Chromium and the ``[browser]`` extra.

    python tests/benchmarks/make_images.py                      # docs/images/*.png + docs/results/images.json
    python tests/benchmarks/make_images.py --out /tmp/img --json /tmp/img/images.json   # (the slow test)
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

from workbench.recording import browser  # noqa: E402
from workbench.recording import moments as km  # noqa: E402
from workbench.recording.reader import read_recording  # noqa: E402

#: (scenario, key moment, image name) of the README's pictures
SHOTS = (
    ("droptest", "max_stroke", "droptest_max_stroke"),
    ("schiaparelli", "pdd", "schiaparelli_pdd"),
    ("msl_meads", "peak_qbar", "msl_meads_peak_qbar"),
    ("post2_huygens", "main_chute", "post2_huygens_main_chute"),
)
SIZE = (1600, 1000)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "images"), help="folder of the PNGs")
    ap.add_argument("--json", default=str(ROOT / "docs" / "results" / "images.json"), help="caption numbers")
    a = ap.parse_args(argv)
    reason = browser.unavailable_reason()
    if reason:
        print(f"make_images: needs {reason}", file=sys.stderr)
        return 2
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results: dict = {"size": list(SIZE), "images": {}}
    ok = True
    with tempfile.TemporaryDirectory(prefix="wb-images-") as tmp:
        rec_dir = Path(tmp) / "recordings"
        names = [s for s, _, _ in SHOTS]
        proc = subprocess.run(
            [sys.executable, "-m", "workbench.cli", "run", *names, "--out", str(rec_dir), "--quiet"],
            capture_output=True,
            text=True,
        )
        if proc.returncode != 0:
            print(proc.stderr[-3000:], file=sys.stderr)
            return 1
        for scenario, moment_name, image in SHOTS:
            rrd = rec_dir / f"{scenario}.rrd"
            data = read_recording(rrd)
            moment = km.find_moment(km.read_key_moments(data), moment_name, where=str(rrd))
            rbl = Path(tmp) / f"{image}.rbl"
            km.write_moment_blueprint(data, moment, rbl)
            shots = Path(tmp) / "shots"
            (check,) = browser.check_recordings([rrd], shots, blueprint=rbl, at=float(moment.t_s), size=SIZE)
            print(check.summary())
            ok &= check.ok
            if check.png is not None:
                shutil.copyfile(check.png, out / f"{image}.png")
            summary = json.loads((rec_dir / f"{scenario}.summary.json").read_text(encoding="utf-8"))
            results["images"][image] = {
                "scenario": scenario,
                "moment": moment_name,
                "t_s": float(moment.t_s),
                "headline": summary.get("headline", ""),
                "verdict": (summary.get("health") or {}).get("verdict"),
                "viewer_ok": bool(check.ok),
                "errors": list(check.errors),
            }
    results["wall_s"] = round(time.perf_counter() - t0, 1)
    write_benchmark_json(a.json, __file__, results, argv)
    print(f"wrote {len(SHOTS)} images to {out} and {a.json} in {results['wall_s']:.0f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
