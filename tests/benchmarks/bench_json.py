"""The one writer of the benchmark JSON convention read by ``make_results.py``.

``{"benchmark": <file stem>, "command": <command line>, "utc": <ISO time>, "machine": "2 cores",
"results": {...}}``; numpy values, NaN and ±inf are converted by ``workbench.io.results.to_jsonable``
(NaN → null). The file is written whole (temporary file + rename), so an interrupted benchmark never
leaves a half-written JSON that a render would read.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shlex
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from workbench.io.results import to_jsonable


def write_benchmark_json(
    path: str | os.PathLike[str], bench_file: str, results: Mapping[str, Any], argv: Sequence[str] | None = None
) -> Path:
    """Write ``results`` of the benchmark script ``bench_file`` (its ``__file__``) to ``path``.

    ``argv``: the script's arguments (default ``sys.argv[1:]``), recorded as the reproducing command
    ``python tests/benchmarks/<script> <args>``. Returns the path written."""
    name = Path(bench_file).name
    words = list(sys.argv[1:] if argv is None else argv)
    doc = {
        "benchmark": Path(bench_file).stem,
        "command": shlex.join(["python", f"tests/benchmarks/{name}", *words]),
        "utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "machine": "2 cores",
        "results": to_jsonable(dict(results)),
    }
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".partial")
    tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, out)
    return out
