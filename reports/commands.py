"""CLI verb of the reports layer: ``mdaug run`` (the whole study)."""
from __future__ import annotations

import argparse
from pathlib import Path


def run_study(args) -> int:
    from .config import StudyConfig, load_config
    from .study import Study

    cfg = load_config(args.config) if args.config else StudyConfig()
    if args.seed is not None:
        cfg.seed = args.seed
    if args.workers is not None:
        cfg.workers = args.workers
    if args.scheduler:
        cfg.scheduler = args.scheduler
    if args.quick:
        cfg = cfg.quick_version()
    cfg.validate()
    results = Study(cfg, args.out).run()
    print(f"\nstudy finished in {results['total_seconds']:.0f} s: {args.out / 'report.html'}, "
          f"{args.out / 'results.json'}")
    for name, s in results["strategies"].items():
        test = "new" if "new" in s["tests"] else next(iter(s["tests"]))
        m = s["tests"][test]
        recalls = {c: v["recall"] for c, v in m["per_class"].items()}
        lo, hi = m["ci"]["accuracy"]
        print(f"  {name:16s} {test}: accuracy {m['accuracy']:.3f} [{lo:.3f}, {hi:.3f}]  "
              f"min recall {min(recalls.values()):.3f}  {recalls}")
    bad = [c for c, r in results["calibration"].items() if not r["converged"]]
    if bad:
        print(f"  WARNING: calibration of {', '.join(bad)} did not converge (see the report's diagnostics)")
    return 0


def register(sub) -> None:
    p = sub.add_parser("run", help="run the whole study and write results.json + report.html",
                       description="Calibrate each class, synthesise training sets (sigma_P and posterior), "
                                   "train the classifiers and the CNN, compare against tsaug, report.")
    p.add_argument("--config", type=Path, default=None, help="study TOML (default: the embedded simulated scene)")
    p.add_argument("--quick", action="store_true", help="small sizes: about a minute")
    p.add_argument("--out", type=Path, default=Path("mdaug-study"), help="output folder (default mdaug-study)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--workers", type=int, default=None, help="local worker processes for independent jobs")
    p.add_argument("--scheduler", default=None,
                   help="dask.distributed scheduler address ('local' starts a LocalCluster)")
    p.set_defaults(func=run_study)
