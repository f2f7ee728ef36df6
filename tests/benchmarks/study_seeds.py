"""How much does one study's answer depend on its seed? Tabulate several finished studies.

    python tests/benchmarks/study_seeds.py STUDY0 STUDY1 ...   # folders of `mdaug run --seed S`

Each seed draws other drones (calibration, selection and test), other nuisances and other
training runs, so the spread between seeds is what a user with other drones should expect.
Per study: the strategy the selection set chose (tied ones together) and each strategy's
CNN balanced accuracy on the test sets (mean over its training runs), with the 95% interval
on the first set, and the ceiling (the classifier trained on the simulator's own data, chosen
on the selection set); then the mean and the lowest-highest over the studies. Nothing is chosen
here: the table only reads what each study chose without its test sets.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from mdaug.reports.readme import load_results
from mdaug.reports.verdicts import ceiling_test


def _row(results: dict, test: str) -> dict:
    out = {}
    for name, s in results["strategies"].items():
        t = s["tests"].get(test)
        if t is not None:
            out[name] = (float(t["balanced_accuracy"]), t.get("ci", {}).get("balanced_accuracy"))
    t = ceiling_test(results, test)
    if t is not None:  # the simulator's own data: what no augmentation can beat
        out["ceiling"] = (float(t["balanced_accuracy"]), t.get("ci", {}).get("balanced_accuracy"))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("studies", nargs="+", help="study folders (or their results.json)")
    ap.add_argument("--tests", default="new,new_large", help="comma-separated test sets (default: %(default)s)")
    a = ap.parse_args(argv)
    tests = [t for t in a.tests.split(",") if t]
    try:
        runs = [(p, load_results(p)) for p in a.studies]
    except (ValueError, FileNotFoundError) as exc:
        print(f"study_seeds: error: {exc}", file=sys.stderr)
        return 2
    names = [*dict.fromkeys(n for _, r in runs for n in r["strategies"]), "ceiling"]
    for test in tests:
        print(f"\nCNN balanced accuracy on '{test}' (mean over training runs"
              + ("; 95% interval" if test == tests[0] else "") + "); * chosen on the selection set")
        head = f"{'seed':>5}  " + "  ".join(f"{n[:19]:>19}" for n in names)
        print(head)
        table = {n: [] for n in names}
        chosen = []  # per study: the chosen strategy's score (tied ones averaged)
        for _, r in runs:
            seed = r["config"].get("seed", "?")
            row = _row(r, test)
            best = [n for n in (r.get("best_strategy") or {}).get("tied") or [] if n in row]
            if best:
                chosen.append(float(np.mean([row[n][0] for n in best])))
            cells = []
            for n in names:
                if n not in row:
                    cells.append(f"{'-':>19}")
                    continue
                ba, ci = row[n]
                table[n].append(ba)
                mark = "*" if n in best else " "
                txt = f"{ba:.3f}{mark}" + (f" [{ci[0]:.2f},{ci[1]:.2f}]" if ci and test == tests[0] else "")
                cells.append(f"{txt:>19}")
            print(f"{seed!s:>5}  " + "  ".join(cells))
        print(f"{'mean':>5}  " + "  ".join(f"{np.mean(v):>19.3f}" if v else f"{'-':>19}" for v in table.values()))
        print(f"{'range':>5}  " + "  ".join(f"{min(v):>13.3f}-{max(v):.3f}" if v else f"{'-':>19}"
                                              for v in table.values()))
        if chosen:
            print(f"the chosen strategy (tied ones averaged): mean {np.mean(chosen):.3f}, "
                  f"{min(chosen):.3f}-{max(chosen):.3f} over {len(chosen)} studies")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
