"""The README's results section, written from a study's ``results.json``, so that the
README's table and the command it quotes cannot drift apart.

The command line is ``tests/benchmarks/readme_table.py``::

    python tests/benchmarks/readme_table.py mdaug-study            # print the section
    python tests/benchmarks/readme_table.py mdaug-study --write    # put it in README.md
    python tests/benchmarks/readme_table.py mdaug-study --check    # exit 1 if a rerun disagrees

The section sits in README.md between :data:`BEGIN` and :data:`END`. It quotes the
``mdaug run`` command that gives the results (seed included) and refuses results whose
configuration that command would not give (other sizes, a config file: their table
would be for another command). Its sentences and verdicts are the report's
(:mod:`.finding`, :mod:`.verdicts`).

What a check accepts (:func:`check_readme`): a rerun of the quoted command whose every
figure in the table (each strategy's and the ceiling's mean balanced accuracy,
accuracy and class recalls) lies within the interval the README quotes for it. The
same machine and library versions give identical files; another CPU rounds
differently, the training runs take other paths, and the figures move within the
quoted intervals, which cover the test sample and the training runs.
"""
from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

from .finding import command, finding
from .markup import Text
from .numbers import column_decimals, spread
from .page_strategies import choice_mark, setting_text
from .verdicts import judge, label

BEGIN = "<!-- results:begin -->"
END = "<!-- results:end -->"
README = Path(__file__).resolve().parents[1] / "README.md"
IGNORED = ("workers", "scheduler", "device")  # how the run was executed, not what it computed


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


def _intervals(m: dict, classes) -> dict:
    """One row's intervals by column: balanced accuracy, accuracy, each class's recall."""
    ci = m.get("ci") or {}
    out = {"balanced": ci.get("balanced_accuracy"), "accuracy": ci.get("accuracy")}
    out.update({c: ((ci.get("per_class") or {}).get(c) or {}).get("recall") for c in classes})
    return out


def _cells(w, m: dict, classes, d: dict) -> list[str]:
    """The figures of one row: balanced accuracy, the runs, accuracy, recalls; ``d``: the
    decimals of each column (one precision per column, :func:`.numbers.column_decimals`)."""
    ci = _intervals(m, classes)
    runs = m.get("n_runs") or 1
    cells = [w.val_ci(None, m["balanced_accuracy"], None, ci["balanced"], d["balanced"]),
             spread(m.get("seed_spread"), d["balanced"]) + f" ({runs})" if runs > 1 else "1 run",
             w.val_ci(None, m["accuracy"], None, ci["accuracy"], d["accuracy"])]
    for c in classes:
        r = (m["per_class"].get(c) or {}).get("recall")
        cells.append(w.val_ci(None, r, None, ci[c], d[c]))
    return cells


COLUMNS = ("balanced accuracy", "runs: lowest–highest (number)", "accuracy")


def results_section(results: dict) -> str:
    """The README's results section (markdown, between the markers) for ``results``."""
    cmd = check_command(results)
    w = Text()
    j = judge(results)
    classes = list(results["config"]["classes"])
    test = j["test"]
    runs = results["config"]["protocol"].get("cnn_seeds", 1)
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
             " ".join(finding(results, w, j)),
             ""]
    if test is not None:
        counts = j["sets"][test]["counts"]
        always = j["sets"][test]["majority"]
        lines.append(f"CNN per strategy on the '{test}' set ({sum(counts.values())} acquisitions: "
                     + ", ".join(f"{n} {c}" for c, n in counts.items()) + f"), the mean of {runs} training runs "
                     "(seeds) with a 95% interval covering the test sample and the training runs"
                     + (f"; always answering {always[0]} scores accuracy {always[1]:.2f}" if always else "") + ":")
        lines.append("")
        head = ["strategy", "setting", *COLUMNS, *(f"recall {c}" for c in classes), "verdict"]
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "|".join("---" for _ in head) + "|")
        verdicts = j["sets"][test]["results"]
        ceil = j.get("ceiling")
        ceil_m = (results["ceiling"]["models"][ceil["model"]]["tests"].get(test) if ceil else None)
        rows = [s["tests"][test] for s in results["strategies"].values() if test in s["tests"]]
        rows += [ceil_m] if ceil_m else []
        ivs = [_intervals(m, classes) for m in rows]
        d = {col: column_decimals([iv[col] for iv in ivs]) for col in ("balanced", "accuracy", *classes)}
        for name, s in results["strategies"].items():
            if test in s["tests"]:
                cells = [name + choice_mark(j, name), setting_text(results, name),
                         *_cells(w, s["tests"][test], classes, d), label(verdicts[name])]
                lines.append("| " + " | ".join(cells) + " |")
        if ceil_m:
            v = j["sets"][test]["ceiling"]
            cells = [f"ceiling: {ceil['model']} trained on the simulator's own data (chosen on the selection set)",
                     "–", *_cells(w, ceil_m, classes, d), label(v)]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    cal = ["Calibration: " + "; ".join(_calibration_text(c, v) for c, v in results["calibration"].items()) + "."]
    lines += cal + ["", END]
    return "\n".join(lines)


def _calibration_text(cls: str, v: dict) -> str:
    """One class's calibration in a line: its status in the words of every other place
    (:func:`mdaug.inference.result.status.calibration_status`), the stored SBC, the
    sampled run where there is one (:func:`~mdaug.inference.result.status.run_facts`;
    a stacked route's weight before its smc part's run), and the route run beside it
    (for the best fit or as a check)."""
    from ..inference.result.status import calibration_status, run_facts

    st = calibration_status(v)
    facts = run_facts(v["diagnostics"])
    text = f"{cls} {st.headline}" + (f" ({st.sbc_facts})" if st.sbc else "")
    if st.route == "stacked":  # the mixture's weight, then the run of its smc part
        text += f"; {st.route_words}" + (f"; its smc run: {facts}" if facts else "")
    elif st.route != "amortized":
        text += f"; {facts}" if facts else ""
    elif st.check:
        text += f"; {st.check}" + (f" ({facts})" if facts else "")
    return text


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


_FIGURE = re.compile(r"^(-?\d+(?:\.\d+)?) \[(-?\d+(?:\.\d+)?), (-?\d+(?:\.\d+)?)\]$")


def table_rows(section: str) -> dict[str, list[str]]:
    """{row name: cells} of the section's markdown table (name without its choice mark)."""
    rows = {}
    for line in section.splitlines():
        if line.startswith("| ") and not line.startswith("| strategy |"):
            cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
            rows[re.sub(r" \((chosen|tied choice)\)$", "", cells[0])] = cells
    return rows


def check_readme(text: str, results: dict) -> list[str]:
    """Why the README's results section does not hold for ``results`` ([] when it does):
    the quoted command must be the one that made them, and every figure of the table
    (the rerun's value, at the README's precision) must lie within the interval the
    README quotes for it."""
    have = current_section(text)
    want = results_section(results)
    problems = []
    cmd = check_command(results)
    if f"```bash\n{cmd}\n```" not in have:
        problems.append(f"the README quotes another command than `{cmd}`\n")
    quoted, rerun = table_rows(have), table_rows(want)
    if set(quoted) != set(rerun):
        problems.append(f"the table's rows differ: README {sorted(quoted)}, rerun {sorted(rerun)}\n")
    head = next((ln for ln in want.splitlines() if ln.startswith("| strategy |")), "")
    names = [c.strip() for c in head.strip().strip("|").split(" | ")]
    for row in sorted(set(quoted) & set(rerun)):
        for col, q, r in zip(names, quoted[row], rerun[row]):
            mq, mr = _FIGURE.match(q), _FIGURE.match(r)
            if not mq:
                continue
            if not mr:
                problems.append(f"{row}, {col}: README {q}, rerun {r}\n")
                continue
            lo, hi = float(mq.group(2)), float(mq.group(3))
            d = len(mq.group(1).split(".")[1]) if "." in mq.group(1) else 0
            value = float(mr.group(1))
            tol = 0.5 * 10.0 ** -d  # the rerun's value is rounded like the README's
            if not lo - tol <= value <= hi + tol:
                problems.append(f"{row}, {col}: rerun {mr.group(1)} outside the README's interval [{lo}, {hi}]\n")
    return problems
