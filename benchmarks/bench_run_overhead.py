"""Benchmark: what ``flexctl run SCENE`` costs beyond its simulations (issue 46, item 5).

Each repetition runs ``flexctl run SCENE --out DIR`` in a fresh process (the compile cache
warm: a first run is made and not counted), measures the process's wall time, and reads from
its ``summary.json`` the wall time of the run (``wall_time_s``) and of the metric errors'
reference run (``slew.errors.reference_wall_time``). The overhead is the rest: interpreter
start, imports, the scene, the design, the loop check, the files and the plot.

Run: ``python benchmarks/bench_run_overhead.py [SCENE ...] [--repeat 5]`` (default scenes:
``bus-slew`` and ``wheel-slew``). Nothing is asserted; the script prints the median and the
best of each quantity (the machine's two cores are shared).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def one_run(scene: str, out: Path) -> dict:
    """Wall times (s) of one ``flexctl run`` in a fresh process."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "flexctl.app.cli", "run", scene, "--out", str(out)],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    total = time.perf_counter() - start
    summary = json.loads((out / "summary.json").read_text())
    errors = (summary.get("slew") or {}).get("errors") or {}
    run, reference = summary["wall_time_s"], errors.get("reference_wall_time", 0.0)
    return {"total": total, "run": run, "reference": reference,
            "overhead": total - run - reference}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["bus-slew", "wheel-slew"])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        for scene in args.scenes:
            one_run(scene, Path(folder) / f"{scene}-warm")
            runs = [one_run(scene, Path(folder) / f"{scene}-{k}") for k in range(args.repeat)]
            print(f"{scene} ({args.repeat} runs, s): " + ", ".join(
                f"{key} median {statistics.median(r[key] for r in runs):.2f} "
                f"best {min(r[key] for r in runs):.2f}"
                for key in ("total", "run", "reference", "overhead")))


if __name__ == "__main__":
    main()
