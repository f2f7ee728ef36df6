"""The README's results section, written from a study's ``results.json``, so that the
README's table and the command it quotes cannot drift apart.

The command line is ``tests/benchmarks/readme_table.py``::

    python tests/benchmarks/readme_table.py mdaug-study            # print the section
    python tests/benchmarks/readme_table.py mdaug-study --write    # put it in README.md
    python tests/benchmarks/readme_table.py mdaug-study --check    # exit 1 if README.md differs

The section sits in README.md between :data:`BEGIN` and :data:`END`. It quotes the
``mdaug run`` command that gives the results (seed included) and refuses results whose
configuration that command would not give (other sizes, a config file: their table
would be for another command).
"""
from __future__ import annotations

import dataclasses
import difflib
import json
from pathlib import Path

from .report import Text, assess, ceiling_best, command, finding, fmt, main_test, majority, set_counts, \
    setting_text, verdict

BEGIN = "<!-- results:begin -->"
END = "<!-- results:end -->"
README = Path(__file__).resolve().parents[1] / "README.md"
IGNORED = ("workers", "scheduler")  # how the run was executed, not what it computed


def load_results(path) -> dict:
    """results.json of a study folder (or the file itself)."""
    p = Path(path)
    if p.is_dir():
        p = p / "results.json"
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no results.json (run `mdaug run --out DIR` first)")
    return json.loads(p.read_text())


def check_command(results: dict) -> str:
    """The ``mdaug run`` command that gives ``results``; ValueError when its configuration
    is not what that command runs (the README could not quote a command for it)."""
    from .config import StudyConfig

    cfg = results["config"]
    if cfg.get("source") not in (None, "defaults"):
        raise ValueError(f"results of a study config ({cfg['source']}): the README quotes the default study")
    expected = StudyConfig(seed=cfg["seed"])
    if cfg.get("quick"):
        expected = expected.quick_version()
    want = json.loads(json.dumps(dataclasses.asdict(expected)))
    got = {k: v for k, v in cfg.items() if k not in IGNORED}
    want = {k: v for k, v in want.items() if k not in IGNORED}
    diff = sorted(f"{sec}.{k}" if isinstance(want.get(sec), dict) else sec
                  for sec in want for k in (want[sec] if isinstance(want[sec], dict) else [None])
                  if (got.get(sec, {}).get(k) if k is not None else got.get(sec))
                  != (want[sec][k] if k is not None else want[sec]))
    if diff:
        raise ValueError(f"these results were not made by `{command(results)}`: settings differ in {', '.join(diff)}")
    return command(results)


def results_section(results: dict) -> str:
    """The README's results section (markdown, between the markers) for ``results``."""
    cmd = check_command(results)
    w = Text()
    classes = list(results["config"]["classes"])
    test = main_test(results)
    lines = [BEGIN,
             "<!-- written by `python tests/benchmarks/readme_table.py DIR --write` from DIR/results.json of the "
             "command below; `--check` verifies it; do not edit by hand -->",
             "",
             "```bash",
             cmd,
             "```",
             "",
             f"Seed {results['config']['seed']}"
             + (" (the default)" if results["config"]["seed"] == 0 else "")
             + ("; simulated scene" if results["simulated"] else "")
             + f"; acquisition: {results['acquisition_text']}.",
             "",
             " ".join(finding(results, w)),
             ""]
    if test is not None:
        counts = set_counts(results, test)
        always = majority(results, test)
        lines.append(f"CNN per strategy on the '{test}' set ({sum(counts.values())} acquisitions: "
                     + ", ".join(f"{n} {c}" for c, n in counts.items()) + "), 95% bootstrap intervals"
                     + (f"; always answering {always[0]} scores accuracy {always[1]:.2f}" if always else "") + ":")
        lines.append("")
        head = ["strategy", "setting", "balanced accuracy", "accuracy", *(f"recall {c}" for c in classes), "verdict"]
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "|".join("---" for _ in head) + "|")
        best = (results.get("best_strategy") or {}).get("name")

        def row(name, setting, m, label_verdict=True):
            ci = m.get("ci") or {}
            cells = [name, setting, w.val_ci(None, m["balanced_accuracy"], None, ci.get("balanced_accuracy")),
                     w.val_ci(None, m["accuracy"], None, ci.get("accuracy"))]
            for c in classes:
                r = (m["per_class"].get(c) or {}).get("recall")
                cells.append(w.val_ci(None, r, None, ((ci.get("per_class") or {}).get(c) or {}).get("recall")))
            cells.append(verdict(assess(m, classes, always), w) if label_verdict else "")
            lines.append("| " + " | ".join(cells) + " |")

        for name, s in results["strategies"].items():
            if test in s["tests"]:
                row(name + (" (chosen)" if name == best else ""), setting_text(results, name), s["tests"][test])
        ceil = ceiling_best(results, test)
        if ceil:
            row(f"ceiling: {ceil[0]} trained on the simulator's own data", "–", ceil[1])
        lines.append("")
    cal = ["Calibration: " + "; ".join(
        f"{c} {'converged' if v['converged'] else 'NOT converged'} (chain "
        f"{fmt(v['diagnostics'].get('steps_over_tau'), 1)} x max tau, "
        f"min ESS {fmt(v['diagnostics'].get('ess_min'), 0)})"
        for c, v in results["calibration"].items()) + "."]
    lines += cal + ["", END]
    return "\n".join(lines)


def replace_section(text: str, section: str) -> str:
    """``text`` with its results section replaced by ``section`` (markers included)."""
    a, b = text.find(BEGIN), text.find(END)
    if a < 0 or b < a:
        raise ValueError(f"README has no results section ({BEGIN} ... {END})")
    return text[:a] + section + text[b + len(END):]


def current_section(text: str) -> str:
    a, b = text.find(BEGIN), text.find(END)
    if a < 0 or b < a:
        raise ValueError(f"README has no results section ({BEGIN} ... {END})")
    return text[a:b + len(END)]


def check_readme(text: str, results: dict) -> list[str]:
    """Differences (unified diff lines) between README ``text``'s results section and the
    section ``results`` give; [] when they agree."""
    have, want = current_section(text), results_section(results)
    if have == want:
        return []
    return list(difflib.unified_diff(have.splitlines(True), want.splitlines(True), "README.md", "results.json"))
