"""Where a ``wand-calib calibrate`` run spends its time: the whole process, then each stage.

Run: .venv/bin/python benchmarks/stages.py [--scenario mocap16] [--placements 10000] [--seed 1]
     .venv/bin/python benchmarks/stages.py --cameras cameras.yaml --observations observations.csv

Without ``--observations`` the data are simulated first (``wand-calib simulate``, 1 px noise) into a
temporary folder. The whole-process figure is what a user sees: ``wand-calib calibrate`` started as a
process, the CSV read and the result written, with its peak RSS; the median of ``--repeats`` runs
(the package's bytecode compiled first, as an installation holds it).
The stage table comes from one more run in this process with the stages' functions wrapped in timers
(inclusive times, stages do not nest; the bundle adjustments inside them are counted separately).
"""

from __future__ import annotations

import argparse
import compileall
import contextlib
import functools
import importlib
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

#: (module, function, stage): the functions timed, in the order a calibration reaches them.
STAGES = (
    ("wand_calib_ros.io.rig_yaml", "load_rig", "read cameras.yaml"),
    ("wand_calib_ros.io.observations_csv", "read_rig_observations", "read the CSV"),
    ("wand_calib_ros.core.pipeline", "check_views", "plausibility of the views"),
    ("wand_calib_ros.core.pipeline", "timing_input", "timing input"),
    ("wand_calib_ros.core.pipeline", "build_vision_graph", "vision graph"),
    ("wand_calib_ros.core.pipeline", "_initialise", "Steps 1-3: pairwise initialisation"),
    ("wand_calib_ros.core.refine", "triangulate_placements", "triangulate the starts"),
    ("wand_calib_ros.core.refine", "_robust_pass", "robust pass (timing tests)"),
    ("wand_calib_ros.core.refine", "adjust_with_model_selection", "model order"),
    ("wand_calib_ros.core.refine", "choose_models", "lens choice (plumb_bob test)"),
    ("wand_calib_ros.core.refine", "readmit", "re-admission"),
    ("wand_calib_ros.core.refine", "_final_adjustment", "final adjustment"),
    ("wand_calib_ros.core.refine", "check_uncertainty", "uncertainty check"),
    ("wand_calib_ros.core.refine", "assemble", "assembly"),
    ("wand_calib_ros.core.pipeline", "check_result", "plausibility of the result"),
    ("wand_calib_ros.core.pipeline", "noise_wand_error", "quality verdict"),
    ("wand_calib_ros.core.pipeline", "clock_offsets", "clock offsets from residuals"),
    ("wand_calib_ros.io.result_yaml", "write_calibration", "write result.yaml"),
)
#: Counted inside the stages: (module, function, label).
INNER = (
    ("wand_calib_ros.core.adjust.bundle_adjustment", "bundle_adjust", "bundle_adjust"),
    ("wand_calib_ros.core.adjust.linearisation", "evaluate", "residuals and normal equations"),
    ("wand_calib_ros.core.adjust.linearisation", "residuals", "residuals alone (costs)"),
    ("wand_calib_ros.core.adjust.placements", "triangulate_placements", "triangulations"),
    ("wand_calib_ros.core.adjust.normal_equations", "reduced_system", "Schur complement"),
    ("wand_calib_ros.core.initialise.pairwise", "initialise_pair", "pair initialisations"),
)


def _wrapped(function: Callable[..., Any], totals: dict[str, list[float]], label: str) -> Callable[..., Any]:
    @functools.wraps(function)
    def timed(*args: Any, **kwargs: Any) -> Any:
        began = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            totals[label].append(time.perf_counter() - began)

    return timed


def _patch(module_name: str, name: str, totals: dict[str, list[float]], label: str, everywhere: bool) -> bool:
    """Wrap ``module.name`` (and with ``everywhere`` every module's import of it); False when it does not exist."""
    module = importlib.import_module(module_name)
    function = getattr(module, name, None)
    if function is None:
        return False
    timed = _wrapped(function, totals, label)
    modules = [m for m in list(sys.modules.values()) if getattr(m, "__name__", "").startswith("wand_calib_ros")]
    for other in modules if everywhere else [module]:
        if getattr(other, name, None) is function:
            setattr(other, name, timed)
    return True


def _stage_table(argv: list[str]) -> None:
    from wand_calib_ros import cli

    for module, _, _ in (*STAGES, *INNER):
        importlib.import_module(module)
    totals: dict[str, list[float]] = defaultdict(list)
    present = [(label, _patch(m, f, totals, label, False)) for m, f, label in STAGES]
    present += [(label, _patch(m, f, totals, label, True)) for m, f, label in INNER]
    began = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        cli.main(["-q", *argv])
    wall = time.perf_counter() - began
    print(f"\nin-process run {wall:.2f} s, by stage (inclusive):")
    staged = 0.0
    for _, _, label in STAGES:
        if label not in totals:
            continue
        seconds = sum(totals[label])
        staged += seconds
        calls = f" ({len(totals[label])} calls)" if len(totals[label]) > 1 else ""
        print(f"  {label:<40} {seconds:6.2f} s  {100 * seconds / wall:4.0f} %{calls}")
    print(f"  {'other (between the stages)':<40} {wall - staged:6.2f} s  {100 * (wall - staged) / wall:4.0f} %")
    for _, _, label in INNER:
        if label in totals:
            print(f"  of which {label:<31} {sum(totals[label]):6.2f} s in {len(totals[label])} calls")
    missing = [label for label, ok in present if not ok]
    if missing:
        print(f"  (not found, not timed: {', '.join(missing)})")


def main() -> None:
    if sys.argv[1:2] == ["--child"]:
        _stage_table(sys.argv[2:])
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="mocap16")
    parser.add_argument("--placements", type=int, default=10000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--cameras", type=Path)
    parser.add_argument("--observations", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--stages-only", action="store_true", help="skip the whole-process runs")
    args = parser.parse_args()
    compileall.compile_dir(str(Path(__file__).resolve().parents[1] / "wand_calib_ros"), quiet=1)  # as installed
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.observations is None:
            command = ["simulate", args.scenario, "--seed", str(args.seed), "--noise", "1.0"]
            command += ["--placements", str(args.placements), "--out", str(folder)]
            subprocess.run([sys.executable, "-m", "wand_calib_ros.cli", "-q", *command], check=True)
            cameras, observations = folder / "cameras.yaml", folder / "observations.csv"
        else:
            cameras, observations = args.cameras, args.observations
        rows = sum(1 for _ in observations.open()) - 1
        calibrate = ["calibrate", "--cameras", str(cameras), "--observations", str(observations)]
        calibrate += ["--output", str(folder / "result.yaml")]
        print(f"{observations} ({rows} rows)")
        if not args.stages_only:
            times, peaks = [], []
            for _ in range(args.repeats):
                began = time.perf_counter()
                child = subprocess.Popen(
                    [sys.executable, "-m", "wand_calib_ros.cli", "-q", *calibrate], stdout=subprocess.DEVNULL
                )
                _, status, usage = os.wait4(child.pid, 0)
                times.append(time.perf_counter() - began)
                child.returncode = os.waitstatus_to_exitcode(status)
                if child.returncode:
                    raise SystemExit(f"wand-calib calibrate failed with exit code {child.returncode}")
                peaks.append(usage.ru_maxrss / 1024)
            print(
                f"wand-calib calibrate as a process: median {statistics.median(times):.2f} s of {len(times)} "
                f"(best {min(times):.2f} s), peak RSS {max(peaks):.0f} MB",
                flush=True,
            )
        subprocess.run([sys.executable, __file__, "--child", *calibrate], check=True)


if __name__ == "__main__":
    main()
