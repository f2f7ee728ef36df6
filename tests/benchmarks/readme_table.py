"""Write or check the README's results section from a study's results.json.

    python tests/benchmarks/readme_table.py mdaug-study            # print the section
    python tests/benchmarks/readme_table.py mdaug-study --write    # put it in README.md
    python tests/benchmarks/readme_table.py mdaug-study --check    # exit 1 if a rerun disagrees

The section (between <!-- results:begin --> and <!-- results:end -->) quotes the
`mdaug run` command whose results it shows, seed included; results from another
configuration are refused (:mod:`mdaug.reports.readme`). ``--check`` accepts a rerun of
that command whose every figure in the table lies within the interval the README quotes
for it (the intervals cover the test sample and the CNNs' training runs; another CPU
moves the figures within them), and says which figure does not.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mdaug.reports.readme import README, check_readme, load_results, replace_section, results_section


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", help="study folder (or its results.json)")
    ap.add_argument("--readme", default=str(README), help="README file (default: %(default)s)")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="replace the README's results section")
    mode.add_argument("--check", action="store_true",
                      help="exit 1 unless the rerun's every figure lies within the README's quoted interval")
    args = ap.parse_args(argv)
    try:
        results = load_results(args.results)
        section = results_section(results)
    except (ValueError, FileNotFoundError) as exc:
        print(f"readme_table: error: {exc}", file=sys.stderr)
        return 2
    path = Path(args.readme)
    if args.write:
        path.write_text(replace_section(path.read_text(), section))
        print(f"{path}: results section written from {args.results}")
        return 0
    if args.check:
        problems = check_readme(path.read_text(), results)
        if not problems:
            print(f"{path}: every figure of {args.results} lies within the README's quoted intervals")
            return 0
        sys.stdout.writelines(problems)
        print(f"\n{path}: {len(problems)} figure(s) of {args.results} disagree with the README", file=sys.stderr)
        return 1
    print(section)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
