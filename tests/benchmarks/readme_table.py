"""Write or check the README's results section from a study's results.json.

    python tests/benchmarks/readme_table.py mdaug-study            # print the section
    python tests/benchmarks/readme_table.py mdaug-study --write    # put it in README.md
    python tests/benchmarks/readme_table.py mdaug-study --check    # exit 1 if README.md differs

The section (between <!-- results:begin --> and <!-- results:end -->) quotes the
`mdaug run` command whose results it shows, seed included; results from another
configuration are refused (:mod:`mdaug.reports.readme`).
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
    mode.add_argument("--check", action="store_true", help="exit 1 when the README's section differs")
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
        diff = check_readme(path.read_text(), results)
        if not diff:
            print(f"{path}: results section matches {args.results}")
            return 0
        sys.stdout.writelines(diff)
        print(f"\n{path}: results section differs from what {args.results} gives", file=sys.stderr)
        return 1
    print(section)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
