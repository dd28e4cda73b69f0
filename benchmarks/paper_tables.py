"""Tables in the style of the paper's Tables 1-4, and the checkerboard baseline comparison.

Run: .venv/bin/python benchmarks/paper_tables.py [--runs 5] [--out docs/paper_tables.md]
For each simulated rig (two conventional, two fisheye, mixed pair, three fisheyes) it calibrates
the same cameras with the wand and with a 7x10 checkerboard (OpenCV fisheye model, the same pixel
noise) and prints one table of parameters (seed 0) and the errors against the truth averaged
(RMS) over ``--runs`` seeds, including D_RMS on the same held-out wand placements.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from wand_calib_ros.sim.comparison import TABLE_SCENARIOS, compare, error_summary, markdown_table

TITLES = {
    "conventional": "Table 1: two conventional cameras",
    "paper": "Table 2: two fisheye cameras",
    "mixed": "Table 3: fisheye (cam0) and conventional (cam1)",
    "paper3": "Table 4: three fisheye cameras",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--noise", type=float, default=1.0)
    parser.add_argument("--out", type=Path, help="also write the Markdown here")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    parts = [f"Simulated rigs, pixel noise {args.noise} px.\n"]
    for name in TABLE_SCENARIOS:
        comparisons = [compare(name, seed, args.noise) for seed in range(args.runs)]
        parts.append(f"### {TITLES[name]}\n\n{markdown_table(comparisons[0])}\n")
        summary = error_summary(comparisons)
        lines = [
            "| errors (RMS over runs and cameras) | focal (px) | principal point (px) | E_r (deg) | E_t | D_RMS (mm) |",
            "|---|---|---|---|---|---|",
        ]
        for method, values in summary.items():
            lines.append(
                f"| {method} | {values['focal']:.2f} | {values['pp']:.2f} | {values['E_r']:.3f} | "
                f"{values['E_t']:.4f} | {values['D_RMS']:.2f} |"
            )
        parts.append(f"{args.runs} runs:\n\n" + "\n".join(lines) + "\n")
    text = "\n".join(parts)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


if __name__ == "__main__":
    main()
