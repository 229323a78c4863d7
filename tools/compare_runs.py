"""Are two runs the same study? Compare their tables (timing left out) and, if asked, the pixels
of their renders, references or method outputs.

    python tools/compare_runs.py RESULTS_A RESULTS_B                      # metrics.csv and every table
    python tools/compare_runs.py RESULTS_A RESULTS_B --images renders outputs
    python tools/compare_runs.py A B --ignore 'mcbench[./][A-Za-z_./]*'    # captions' module paths left out

Prints a Markdown report (one row per table or file that differs, with the largest absolute and
relative difference of its numbers) and exits 1 when anything differs, 0 when the runs agree.
What is compared and how: :mod:`mcbench.analysis.run_comparison`.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mcbench.analysis.run_comparison import compare_images, compare_runs, table_paths  # noqa: E402


def _number(value: float | int | None) -> str:
    return "" if value is None else f"{value:.3g}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results_a", type=Path, help="results folder of the first run")
    parser.add_argument("results_b", type=Path, help="results folder of the second run")
    parser.add_argument("--images", nargs="*", default=[], metavar="FOLDER",
                        help="folders under results/ whose EXR files are compared pixel by pixel (renders, references, outputs)")
    parser.add_argument("--ignore", type=re.compile, default=None, metavar="REGEX",
                        help="text left out of every table before comparing (e.g. module paths a refactoring renamed)")
    args = parser.parse_args(argv)
    tables = table_paths(args.results_a)
    differences = compare_runs(args.results_a, args.results_b, ignore=args.ignore)
    print(f"# {args.results_a} against {args.results_b}\n")
    print(f"{len(tables)} tables (metrics.csv and every CSV/Markdown/LaTeX file under "
          f"tables/, oracle/, progressive/), timing left out"
          f"{'' if args.ignore is None else f' and text matching {args.ignore.pattern!r}'}: {len(differences)} differ.")
    for folder in args.images:
        count = sum(1 for _ in (args.results_a / folder).rglob("*.exr"))
        found = compare_images(args.results_a, args.results_b, folder)
        print(f"{count} EXR files under {folder}/: {len(found)} differ.")
        differences += found
    if differences:
        print("\n| file | status | differing values | max abs | max rel |\n| --- | --- | --- | --- | --- |")
        for d in differences:
            print(f"| {d.table} | {d.status} | {_number(d.cells)} | {_number(d.max_abs)} | {_number(d.max_rel)} |")
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
