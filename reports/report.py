"""The study's report: one self-contained HTML file (figures embedded as PNG data),
read from the top: the finding in a few generated sentences, one figure of the
strategies, the calibration per class, the choices and their sweeps, measured against
synthetic profiles, speed against error; the rest folded away.

Conventions of the page:

* every number taken from ``results.json`` carries ``data-key``, its path there
  (dot-separated), so the report and the results can be checked against each other;
* a number with an interval is rounded to its interval's precision (the Particle
  Data Group's rule on the half-width, :func:`decimals`: 0.08 gives 2 decimals);
* an undefined value (a precision of a class never predicted) reads "–";
* results that are degenerate (a class never recognised), not better than chance
  (balanced-accuracy interval containing 0.5) or no better than always answering the
  majority class are labelled as such;
* no raw JSON or Python repr anywhere; every image has alt text.
"""
from __future__ import annotations

import base64
import html
import json
import math
import os
from importlib import resources
from pathlib import Path

import numpy as np

from ..radar import atomic_write

SECTIONS = ("finding", "strategies", "calibration", "choice", "profiles", "speed", "details")

CSS = """body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;max-width:1080px;margin:auto;
padding:1em 1.2em;line-height:1.45;color:#222}
h1{font-size:1.6em;margin-bottom:.3em}h2{border-bottom:1px solid #ddd;padding-bottom:.15em;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.95em}td,th{border:1px solid #d4d4d4;padding:3px 7px;
vertical-align:top}th{background:#f3f3f3;text-align:left}td.n{text-align:right;white-space:nowrap}
tr.chosen td{background:#eef5fc}td.verdict{min-width:13em}.ci{color:#666;font-size:.85em;white-space:nowrap}
.warn{color:#b00020;font-weight:600}.flag{color:#b00020}.ok{color:#1b7a3a;font-weight:600}
img{max-width:100%;height:auto;display:block;margin:.4em 0}
.headline{font-size:1.12em;background:#f6f8fa;border-left:4px solid #1f78b4;padding:.6em .9em;margin:.6em 0}
details{margin:.6em 0;border:1px solid #e2e2e2;border-radius:4px;padding:.3em .7em}
summary{cursor:pointer;font-weight:600}.note{color:#555;font-size:.93em}nav{font-size:.95em}
nav a{margin-right:1em}code{background:#f3f3f3;padding:0 .25em}"""


# ---- access and number formatting --------------------------------------------------------------
def published_results() -> dict:
    """The published study's figures (packaged copy of reference/published_results.json)."""
    return json.loads(resources.files("mdaug.reports").joinpath("data/published_results.json").read_text())


def get(results: dict, key: str):
    v = results
    for part in key.split("."):
        v = v[part] if isinstance(v, dict) else v[int(part)]
    return v


def decimals(interval, default: int = 2, lo: int = 1, hi: int = 4) -> int:
    """Decimals that round a number to its interval's precision, by the Particle Data
    Group's rule on the half-width h: its three leading digits 100-354 keep two
    significant digits, 355-949 one, 950-999 round up to 1000 and keep two
    (h = 0.08 -> 2 decimals, 0.12 -> 2, 0.04 -> 2, 0.03 -> 3, 0.4 -> 1); within [lo, hi];
    ``default`` when there is no interval or it has no width."""
    if not interval or interval[0] is None or interval[1] is None:
        return default
    h = (float(interval[1]) - float(interval[0])) / 2.0
    if not np.isfinite(h) or h <= 0:
        return default
    e = math.floor(math.log10(h))
    lead = int(round(h / 10.0 ** (e - 2)))
    if lead >= 1000:  # h = 9.995... rounded up a decade
        e, lead = e + 1, 100
    sig = 2 if lead <= 354 else 1 if lead <= 949 else 2
    if lead >= 950:
        e += 1
    return int(min(max(sig - 1 - e, lo), hi))


def fmt(v, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return f"{v:.{max(digits, 0)}f}"
    return html.escape(str(v))


def fmt_sig(v, sig: int = 2) -> str:
    """A number to ``sig`` significant digits (scientific below 1e-3)."""
    if v is None or not np.isfinite(v):
        return "–"
    if v == 0:
        return "0"
    if abs(v) < 1e-3:
        return f"{v:.{sig - 1}e}"
    d = max(sig - 1 - math.floor(math.log10(abs(v))), 0)
    return f"{v:.{d}f}"


class Html:
    """Formatting for the page (numbers tagged with their results.json key)."""

    @staticmethod
    def esc(s) -> str:
        return html.escape(str(s))

    @staticmethod
    def b(s) -> str:
        return f"<b>{html.escape(str(s))}</b>"

    @staticmethod
    def num(key: str | None, value, d: int = 2) -> str:
        text = fmt(value, d)
        if key is None or text == "–":
            return text
        return f'<span data-key="{html.escape(key)}">{text}</span>'

    def val_ci(self, key: str | None, value, ci_key: str | None, ci, d: int | None = None, br: bool = False) -> str:
        d = decimals(ci) if d is None else d
        s = self.num(key, value, d)
        if ci:
            s += ("<br>" if br else " ") + (f'<span class="ci">[{self.num(ci_key and ci_key + ".0", ci[0], d)}, '
                  f'{self.num(ci_key and ci_key + ".1", ci[1], d)}]</span>')
        return s


class Text(Html):
    """Formatting for the README (markdown, plain numbers)."""

    @staticmethod
    def esc(s) -> str:
        return str(s)

    @staticmethod
    def b(s) -> str:
        return f"**{s}**"

    @staticmethod
    def num(key, value, d: int = 2) -> str:
        return fmt(value, d)

    def val_ci(self, key, value, ci_key, ci, d=None, br=False) -> str:
        d = decimals(ci) if d is None else d
        return fmt(value, d) + (f" [{fmt(ci[0], d)}, {fmt(ci[1], d)}]" if ci else "")


# ---- reading the results -------------------------------------------------------------------------
def main_test(results: dict) -> str | None:
    """The test set the finding is about: 'new' (new drones) when there is one."""
    sel = results["selection"]["set"]
    names = [t for s in results["strategies"].values() for t in s["tests"] if t != sel]
    if not names:
        return None
    return "new" if "new" in names else names[0]


def test_sets(results: dict) -> list[str]:
    sel = results["selection"]["set"]
    return list(dict.fromkeys(t for s in results["strategies"].values() for t in s["tests"] if t != sel))


def set_counts(results: dict, test: str, m: dict | None = None) -> dict:
    """{class: count} of a set (from the data index, else from a metrics dict)."""
    d = (results.get("data") or {}).get(test)
    if d and d.get("per_class"):
        return {c: int(n) for c, n in d["per_class"].items()}
    return {c: int(v["n"]) for c, v in (m or {}).get("per_class", {}).items()}


def majority(results: dict, test: str, m: dict | None = None):
    """(class, accuracy of always answering it) of an imbalanced set; None if balanced."""
    counts = set_counts(results, test, m)
    n = sum(counts.values())
    if not n or len(set(counts.values())) <= 1:
        return None
    cls = max(counts, key=counts.get)
    return cls, counts[cls] / n


def assess(m: dict, classes, always=None) -> dict:
    """What a metrics dict says beyond its numbers: degenerate (a class never recognised),
    never-predicted classes (their precision is undefined), chance, majority, bias."""
    cm = np.asarray(m["confusion_matrix"])
    labels = list(m["labels"])
    never_predicted = [labels[j] for j in range(len(labels)) if cm[:, j].sum() == 0]
    recalls = {c: (m["per_class"].get(c) or {}).get("recall") for c in classes}
    zero = [c for c, r in recalls.items() if r == 0.0]
    ci = (m.get("ci") or {})
    bal_ci = ci.get("balanced_accuracy")
    out = {"degenerate": bool(zero), "zero_recall": zero, "never_predicted": never_predicted,
           "chance": None, "below_majority": None, "biased_towards": None}
    if bal_ci:
        if bal_ci[1] < 0.5:
            out["chance"] = "worse than chance"
        elif bal_ci[0] <= 0.5:
            out["chance"] = "not better than chance"
    if always is not None and m["accuracy"] <= always[1] + 1e-12:
        out["below_majority"] = always
    rc = {c: ((ci.get("per_class") or {}).get(c) or {}).get("recall") for c in classes}
    known = {c: r for c, r in recalls.items() if r is not None}
    if len(known) >= 2:
        top = max(known, key=known.get)
        bottom = min(known, key=known.get)
        if top != bottom:
            if zero or (rc.get(top) and rc.get(bottom) and rc[top][0] > rc[bottom][1]):
                out["biased_towards"] = top
    return out


def verdict(a: dict, w=Html()) -> str:
    """The labels of :func:`assess` as short text ('' when there is nothing to say)."""
    parts = []
    if a["degenerate"]:
        z = ", ".join(a["zero_recall"])
        never = [c for c in a["never_predicted"] if c in a["zero_recall"]]
        parts.append(f"degenerate: recognises no {z}" + (f" (never predicts {', '.join(never)})" if never else ""))
    elif a["biased_towards"]:
        parts.append(f"biased towards {a['biased_towards']}")
    if a["chance"]:
        parts.append(a["chance"])
    if a["below_majority"]:
        cls, acc = a["below_majority"]
        parts.append(f"accuracy no better than always answering {cls} ({acc:.2f})")
    return "; ".join(parts)


def _diff_interval(m1: dict, m2: dict, n_boot: int = 4000, seed: int = 0):
    """Balanced accuracy of m1 minus m2 and a 95% interval: per-class recalls drawn
    binomially from each confusion matrix, the two independently (the predictions'
    pairing is not in the results, so the interval is the wider, unpaired one)."""
    rng = np.random.default_rng(seed)

    def draws(m):
        cm = np.asarray(m["confusion_matrix"], float)
        n = cm.sum(axis=1)
        rows = [rng.binomial(int(k), cm[i, i] / k, size=n_boot) / k for i, k in enumerate(n) if k > 0]
        return np.mean(rows, axis=0)

    d = draws(m1) - draws(m2)
    lo, hi = np.percentile(d, [2.5, 97.5])
    return m1["balanced_accuracy"] - m2["balanced_accuracy"], [float(lo), float(hi)]


def ceiling_best(results: dict, test: str):
    """(model, metrics) of the ceiling model with the best balanced accuracy on ``test``."""
    models = (results.get("ceiling") or {}).get("models") or {}
    scored = [(k, v["tests"][test]) for k, v in models.items() if test in v["tests"]]
    if not scored:
        return None
    return max(scored, key=lambda kv: kv[1]["balanced_accuracy"])


def setting_text(results: dict, name: str) -> str:
    s = results["strategies"][name]
    for key, label in (("sigma_p", "sigma_P"), ("width", "width")):
        if s.get(key) is not None:
            return f"{label} = {s[key]:g}"
    return "–"


def _list(names) -> str:
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


# ---- the finding -----------------------------------------------------------------------------------
def signed(d: float, ci) -> str:
    """A difference and its interval, signed, at the interval's precision: '+0.06 [-0.03, +0.15]'."""
    dd = decimals(ci)
    f = lambda v: f"{round(v, dd) + 0.0:+.{dd}f}"  # noqa: E731  (+ 0.0: no '-0.00')
    return f"{f(d)} [{f(ci[0])}, {f(ci[1])}]"


def finding(results: dict, w=Html()) -> list[str]:
    """Two or three sentences, generated from the results: which strategy wins on new
    drones and by how much (intervals), against tsaug and the ceiling; which
    strategies are biased, and towards which class."""
    test = main_test(results)
    best = (results.get("best_strategy") or {}).get("name")
    if test is None or best is None:
        return ["No strategy could be ranked: the study has no test set or no strategy scored on the selection set."]
    classes = list(results["config"]["classes"])
    strategies = results["strategies"]
    key = lambda n, *rest: ".".join(["strategies", n, "tests", test, *rest])  # noqa: E731

    def score(n):
        m = strategies[n]["tests"][test]
        return w.val_ci(key(n, "balanced_accuracy"), m["balanced_accuracy"], key(n, "ci", "balanced_accuracy"),
                        (m.get("ci") or {}).get("balanced_accuracy"))

    m = strategies[best]["tests"][test]
    counts = set_counts(results, test, m)
    always = majority(results, test, m)
    scored = [n for n, s in strategies.items() if test in s["tests"]]
    verdicts = {n: assess(strategies[n]["tests"][test], classes, always) for n in scored}
    what = "new drones" if test.startswith("new") else f"the '{w.esc(test)}' set"
    where = (f"On {what} (the '{w.esc(test)}' set of {sum(counts.values())} acquisitions, "
             f"{_list([f'{n} {c}' for c, n in counts.items()])})")
    chosen = f"the strategy chosen without the test set, {w.b(best)}"
    top = None
    if all(v["chance"] for v in verdicts.values()):
        s1 = (f"{where}, no strategy's CNN is better than chance: every balanced-accuracy interval contains 0.5; "
              f"{chosen}, has balanced accuracy {score(best)}.")
    else:
        s1 = f"{where}, {chosen}, gives a CNN with balanced accuracy {score(best)}"
        large = [t for t in strategies[best]["tests"] if t != test and t.startswith(test)]
        if large:  # the same kind of drones, more of them: a tighter interval
            t2 = large[0]
            m2 = strategies[best]["tests"][t2]
            k2 = f"strategies.{best}.tests.{t2}"
            big = w.val_ci(k2 + ".balanced_accuracy", m2["balanced_accuracy"], k2 + ".ci.balanced_accuracy",
                           (m2.get("ci") or {}).get("balanced_accuracy"))
            s1 += f" ({big} on the larger '{w.esc(t2)}' set of {m2['n']})"
        # the best other strategy on this set, among those that are neither degenerate nor at chance
        others = [n for n in scored if n != best and not verdicts[n]["degenerate"] and not verdicts[n]["chance"]]
        top = max(others, key=lambda n: strategies[n]["tests"][test]["balanced_accuracy"]) if others else None
        if top is None:
            s1 += "; every other strategy is degenerate or not better than chance."
        elif m["balanced_accuracy"] >= strategies[top]["tests"][test]["balanced_accuracy"]:
            d, ci = _diff_interval(m, strategies[top]["tests"][test])
            s1 += (f"; it is the best of the {len(scored)} strategies there, "
                   + (f"ahead of the next, {w.esc(top)}, by {signed(d, ci)}." if ci[0] > 0 else
                      f"level with the next, {w.esc(top)} (difference {signed(d, ci)}, an interval containing 0)."))
        else:
            d, ci = _diff_interval(strategies[top]["tests"][test], m)
            if ci[0] > 0:
                s1 += (f"; the best on this set is {w.b(top)}, {score(top)} (difference {signed(d, ci)}), but it "
                       "was not the choice made on the selection set.")
            else:
                s1 += (f"; {w.b(top)} scores {score(top)} on this set, level with it (difference "
                       f"{signed(d, ci)}, an interval containing 0).")
    others = [n for n in scored if n != best]
    parts = []
    if "tsaug" in others and top != "tsaug":
        d, ci = _diff_interval(m, strategies["tsaug"]["tests"][test])
        parts.append(f"against tsaug ({score('tsaug')}) the difference is {signed(d, ci)}")
    ceil = ceiling_best(results, test)
    if ceil:
        model, cm = ceil
        d, ci = _diff_interval(m, cm)
        ck = f"ceiling.models.{model}.tests.{test}"
        parts.append(f"against the ceiling of the simulated scene ({w.esc(model)} trained on the simulator's own "
                     "data, " + w.val_ci(f"{ck}.balanced_accuracy", cm["balanced_accuracy"],
                                          f"{ck}.ci.balanced_accuracy", (cm.get("ci") or {}).get("balanced_accuracy"))
                     + f") it is {signed(d, ci)}")
    sentences = [s1]
    if parts:
        text = "; ".join(parts)
        sentences.append(text[0].upper() + text[1:] + f" ({w.esc(best)} minus the other, in balanced accuracy; "
                         "95% intervals, unpaired).")
    biased, chance = {}, []
    for n in scored:
        a = verdicts[n]
        if a["biased_towards"]:
            biased.setdefault(a["biased_towards"], []).append(n + (" (degenerate)" if a["degenerate"] else ""))
        if a["chance"]:
            chance.append(n)
    if biased:
        s3 = ("Biased (class recalls whose intervals do not overlap): "
              + "; ".join(f"{_list(v)} towards {c}" for c, v in biased.items()))
    else:
        s3 = "No strategy is biased towards one class beyond its intervals"
    if chance and len(chance) < len(scored):
        s3 += f"; not better than chance (a balanced-accuracy interval containing 0.5): {_list(chance)}"
    sentences.append(s3 + ".")
    return sentences


def context(results: dict, w=Html()) -> str:
    """What the finding is about: the data, the acquisition, the seed, and the caveats."""
    what = ("All measurements are <b>simulated</b> by mdaug's scene simulator (new drones: other specimens "
            "of each class)." if results["simulated"] else "Measured data from the files of the study config.")
    cfg = results["config"]
    text = (f"{what} Acquisition: {w.esc(results['acquisition_text'])}. Seed {cfg['seed']}"
            f"{', quick sizes' if cfg.get('quick') else ''}; command <code>{w.esc(command(results))}</code>.")
    bad = [c for c, cal in results["calibration"].items() if not cal["converged"]]
    if bad:
        text += (f" <span class='warn'>Calibration of {_list(bad)} did not converge</span> (its chain is shorter "
                 "than the convergence rule asks; see Calibration): the posterior-based strategies rest on it.")
    return text


def command(results: dict) -> str:
    """The ``mdaug run`` command that gives these results (the config file, when one was used)."""
    cfg = results["config"]
    parts = ["mdaug run"]
    if cfg.get("source") not in (None, "defaults"):
        parts.append(f"--config {cfg['source']}")
    if cfg.get("quick"):
        parts.append("--quick")
    parts.append("--out mdaug-study")
    if cfg.get("seed", 0) != 0:
        parts.append(f"--seed {cfg['seed']}")
    return " ".join(parts)


# ---- page pieces ---------------------------------------------------------------------------------
class Figures:
    """Saves the report's figures next to it (figures/report_*.png) and embeds them."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)

    def embed(self, name: str, fig, alt: str) -> str:
        if fig is None:
            return ""
        from .style import save

        self.folder.mkdir(parents=True, exist_ok=True)
        path = save(fig, self.folder / f"report_{name}.png")
        return img(path, alt)


def img(path, alt: str) -> str:
    p = Path(path) if path else None
    if p is None or not p.is_file():
        return f"<p class='note'>(figure {html.escape(Path(str(path)).name)} is missing)</p>"
    data = base64.b64encode(p.read_bytes()).decode()
    return f'<img src="data:image/png;base64,{data}" alt="{html.escape(alt)}"/>'


def section(sid: str, title: str, body: str) -> str:
    return f'<section id="{sid}"><h2>{html.escape(title)}</h2>\n{body}\n</section>'


def details(summary: str, body: str) -> str:
    return f"<details><summary>{html.escape(summary)}</summary>\n{body}\n</details>"


def table(head: list[str], rows: list[list[str]], row_class: list[str] | None = None) -> str:
    h = "".join(f"<th>{c}</th>" for c in head)
    body = []
    for i, cells in enumerate(rows):
        cls = row_class[i] if row_class else ""
        body.append((f'<tr class="{cls}">' if cls else "<tr>") + "".join(cells) + "</tr>")
    return f"<table><tr>{h}</tr>{''.join(body)}</table>"


def td(s: str, num: bool = True) -> str:
    return f"<td class='n'>{s}</td>" if num else f"<td>{s}</td>"


def _metric_cells(w: Html, base: str, m: dict, classes, precision: bool = True) -> list[str]:
    ci = m.get("ci") or {}
    cells = [td(w.val_ci(f"{base}.balanced_accuracy", m["balanced_accuracy"], f"{base}.ci.balanced_accuracy",
                         ci.get("balanced_accuracy"), br=True)),
             td(w.val_ci(f"{base}.accuracy", m["accuracy"], f"{base}.ci.accuracy", ci.get("accuracy"), br=True))]
    cm = np.asarray(m["confusion_matrix"])
    labels = list(m["labels"])
    for c in classes:
        pc = m["per_class"].get(c) or {}
        cc = (ci.get("per_class") or {}).get(c) or {}
        cells.append(td(w.val_ci(f"{base}.per_class.{c}.recall", pc.get("recall"),
                                 f"{base}.ci.per_class.{c}.recall", cc.get("recall"), br=True)))
    if precision:
        for c in classes:
            pc = m["per_class"].get(c) or {}
            cc = (ci.get("per_class") or {}).get(c) or {}
            j = labels.index(c) if c in labels else None
            if j is None or cm[:, j].sum() == 0:  # never predicted: precision undefined
                cells.append(td("–"))
            else:
                cells.append(td(w.val_ci(f"{base}.per_class.{c}.precision", pc.get("precision"),
                                         f"{base}.ci.per_class.{c}.precision", cc.get("precision"), br=True)))
    return cells


def _strategy_table(r: dict, test: str, w: Html) -> str:
    """Every strategy's CNN on set ``test``: the metrics with intervals, the selection
    set's balanced accuracy (the ranking; not repeated on the selection set) and verdicts."""
    classes = list(r["config"]["classes"])
    sel = r["selection"]["set"]
    best = (r.get("best_strategy") or {}).get("name")
    always = majority(r, test)
    head = (["strategy<br><span class='ci'>setting</span>", "balanced accuracy", "accuracy"]
            + [f"recall {c}" for c in classes] + [f"precision {c}" for c in classes]
            + ([f"balanced accuracy on '{html.escape(sel)}' (the selection set)"] if test != sel else [])
            + ["verdict"])
    rows, cls = [], []
    for name, s in r["strategies"].items():
        if test not in s["tests"]:
            continue
        m = s["tests"][test]
        base = f"strategies.{name}.tests.{test}"
        setting = setting_text(r, name)
        cells = [td(w.esc(name) + (" <b>(chosen)</b>" if name == best else "")
                    + (f"<br><span class='ci'>{w.esc(setting)}</span>" if setting != "–" else ""), False)]
        cells += _metric_cells(w, base, m, classes)
        ms = s["tests"].get(sel)
        if test != sel:
            cells.append(td(w.val_ci(f"strategies.{name}.tests.{sel}.balanced_accuracy", ms["balanced_accuracy"],
                                     f"strategies.{name}.tests.{sel}.ci.balanced_accuracy",
                                     (ms.get("ci") or {}).get("balanced_accuracy"), br=True) if ms else "–"))
        v = verdict(assess(m, classes, always))
        flag = f'<span class="flag">{v}</span>' if v else ""
        cells.append(f"<td class='verdict'>{flag}</td>")
        rows.append(cells)
        cls.append("chosen" if name == best else "")
    return table(head, rows, cls)


def _majority_note(r: dict, test: str) -> str:
    counts = set_counts(r, test)
    n = sum(counts.values())
    always = majority(r, test)
    per_class = ", ".join(f"{v} {c}" for c, v in counts.items())
    text = f"The '{html.escape(test)}' set holds {n} acquisitions ({per_class})."
    if always:
        text += (f" It is imbalanced: always answering {always[0]} scores accuracy {always[1]:.2f} (balanced "
                 "accuracy 0.50), so accuracy alone says little; balanced accuracy (the mean of the class recalls) "
                 "is the figure to read.")
    return f"<p class='note'>{text}</p>"


def strategies_section(r: dict, figs: Figures, w: Html) -> str:
    from . import figures

    test = main_test(r)
    if test is None:
        return "<p>No test set.</p>"
    classes = list(r["config"]["classes"])
    best = (r.get("best_strategy") or {}).get("name")
    ceil = ceiling_best(r, test)
    ceiling = (f"{ceil[0]} on simulated scenes", ceil[1]["balanced_accuracy"],
               (ceil[1].get("ci") or {}).get("balanced_accuracy")) if ceil else None
    out = [figs.embed("strategies", figures.strategies_figure(r, test, best, ceiling),
                      f"Balanced accuracy and per-class recall with 95% intervals of every strategy's CNN on the "
                      f"'{test}' set, with chance and the simulated scene's ceiling as lines"),
           _majority_note(r, test), _strategy_table(r, test, w),
           "<p class='note'>Intervals: 95% bootstrap. Recall of a class is the share of its acquisitions "
           "classified correctly (the published per-class 'precision'); precision is the share of the "
           "acquisitions predicted as the class that are of it (a dash: the class is never predicted, precision is "
           "undefined). Verdicts: <i>degenerate</i>, a class never recognised; <i>biased</i>, class recalls whose "
           "intervals do not overlap; <i>not better than chance</i>, a balanced-accuracy interval that contains "
           "0.5.</p>",
           "<ul>" + "".join(f"<li><b>{w.esc(n)}</b>: {w.esc(t)}</li>" for n, t in r["strategy_text"].items())
           + "</ul>"]
    more = []
    for t in test_sets(r):
        if t == test:
            continue
        more.append(f"<h4>'{w.esc(t)}' set</h4>" + _majority_note(r, t) + _strategy_table(r, t, w))
    sel = r["selection"]["set"]
    more.append(f"<h4>Selection set '{w.esc(sel)}' (the choices are made here)</h4>"
                + _majority_note(r, sel) + _strategy_table(r, sel, w))
    out.append(details("Other sets: the same table on every other set", "".join(more)))
    out.append(details(f"Confusion matrices on '{test}'",
                       figs.embed("confusion", figures.confusion_figure(r, test),
                                  f"Confusion matrices of every strategy's CNN on the '{test}' set, each titled with "
                                  "its balanced accuracy and 95% interval")))
    if r.get("ceiling"):
        c = r["ceiling"]
        what = c.get("what", "")
        rows = []
        for model, cm in c["models"].items():
            for t, m in cm["tests"].items():
                rows.append([td(w.esc(model), False), td(w.esc(t), False)]
                            + _metric_cells(w, f"ceiling.models.{model}.tests.{t}", m, classes, precision=False)
                            + [td(w.num(f"ceiling.models.{model}.train_seconds", cm["train_seconds"], 2))])
        out.append(details("The ceiling: classifiers trained on the simulator's own data",
                           f"<p>{w.esc(what[:1].upper() + what[1:])}. No augmentation of a few measurements "
                           "should beat it: it is what the acquisition leaves of the class difference.</p>"
                           + table(["model", "set", "balanced accuracy", "accuracy"]
                                   + [f"recall {k}" for k in classes] + ["training (s)"], rows)))
    return "\n".join(out)


def _sbc_text(cal: dict, w: Html) -> str:
    sbc = cal.get("sbc")
    if not sbc:
        return "not run in the study (see README: SBC)."
    share = sbc.get("outer_share")
    p = sbc.get("pooled_p")
    n = sbc.get("n_replicates")
    ok = False
    if share is not None and p is not None and n:
        from scipy.stats import binom

        lo, hi = binom.ppf([0.025, 0.975], int(n), 0.1) / int(n)  # an honest sampler's range of the share
        ok = p > 0.05 and lo <= share <= hi
    return (f"{fmt(n)} replicates: {fmt(share, 2)} of the truths in the outer 10% of their posterior (0.10 "
            f"if honest), pooled rank p = {fmt_sig(p)}: "
            + ("<span class='ok'>consistent with a calibrated posterior</span>" if ok else
               "<span class='warn'>the posterior is not calibrated</span>") + ".")


def _lines_table(cal: dict) -> str:
    lines = cal.get("lines")
    if not lines:
        return ""
    fq = np.asarray(lines["frequency_q"], float) / (2 * np.pi)
    aq = np.asarray(lines["amplitude_q"], float) * 1e3
    rows = []
    for k in range(fq.shape[1]):
        for j in range(fq.shape[2]):
            f_ci, a_ci = [fq[0, k, j], fq[2, k, j]], [aq[0, k, j], aq[2, k, j]]
            fd = min(decimals(f_ci, 0, -3, 2), 0) if f_ci[1] > f_ci[0] else 0
            ad = decimals(a_ci, 2, 1, 4)
            f = lambda v: f"{round(v, fd):,.0f}" if fd <= 0 else f"{v:,.{fd}f}"  # noqa: E731
            rows.append([td(str(k)), td(str(j + 1)),
                         td(f"{f(fq[1, k, j])} <span class='ci'>[{f(f_ci[0])}, {f(f_ci[1])}]</span>"),
                         td(f"{fmt(aq[1, k, j], ad)} <span class='ci'>[{fmt(a_ci[0], ad)}, {fmt(a_ci[1], ad)}]"
                            "</span>")])
    return table(["engine", "line (by frequency)", "frequency (Hz): median [5%, 95%]",
                  "amplitude (mm): median [5%, 95%]"], rows)


def _acquisition_compare(cal: dict) -> str:
    st, me = cal.get("acquisition") or {}, cal.get("measured_acquisition") or {}
    bits = []
    for key, label, unit, d in (("carrier", "carrier return", " x sum(Gamma)", 2),
                                ("noise_db", "noise floor", " dB", 0)):
        if st.get(key) and me.get(key) and st[key] != me[key]:
            bits.append(f"{label} measured {me[key][0]:.{d}f} to {me[key][1]:.{d}f}{unit} "
                        f"(the campaign states {st[key][0]:.{d}f} to {st[key][1]:.{d}f}{unit})")
    if not bits:
        return ""
    return "<p class='note'>What the calibration measured of the acquisition: " + "; ".join(bits) + ".</p>"


def calibration_section(r: dict, figs: Figures, w: Html, report_dir: Path) -> str:
    from . import figures

    out = ["<p class='note'>Each class is calibrated on its few measurements under the campaign's acquisition "
           "(phases marginalised). A vibration model is a sum of four lines per engine; which line is the roll, "
           "the pitch or a mixing term is a labelling one profile cannot fix, so the posterior is shown label-free: "
           "every line's frequency and amplitude, lines sorted by frequency.</p>"]
    for cls, c in r["calibration"].items():
        d = c["diagnostics"]
        k = f"calibration.{cls}.diagnostics"
        status = ("<span class='ok'>converged</span>" if c["converged"] else "<span class='warn'>NOT CONVERGED</span>")
        reason = w.esc(d.get("reason", ""))
        for prefix in ("NOT CONVERGED: ", "converged: ", "Converged: "):
            reason = reason[len(prefix):] if reason.startswith(prefix) else reason
        sampler = d.get("sampler", "emcee")
        if sampler == "smc":
            chain = f"SMC, {fmt(d.get('smc_n_particles'))} particles, {fmt(d.get('smc_stages'))} stages"
        else:
            chain = (f"{fmt(d.get('n_walkers'))} walkers x {fmt(d.get('chain_steps'))} steps (chain = "
                     f"{w.num(k + '.steps_over_tau', d.get('steps_over_tau'), 1)} x max tau)")
        out.append(f"<h3>{w.esc(cls)}: {status}</h3>")
        reason = reason[:1].upper() + reason[1:]
        out.append(f"<ul><li><b>Convergence</b>: {reason}.</li>"
                   f"<li><b>Sampler</b>: {chain}; min ESS {w.num(k + '.ess_min', d.get('ess_min'), 0)}; acceptance "
                   f"{w.num(k + '.acceptance_mean', d.get('acceptance_mean'), 2)}; "
                   f"{w.num(k + '.seconds', d.get('seconds'), 0)} s on {fmt(c.get('n_profiles'))} measurements.</li>"
                   f"<li><b>SBC</b>: {_sbc_text(c, w)}</li></ul>")
        if c.get("lines"):
            out.append(figs.embed(f"posterior_{cls}", figures.posterior_lines_figure(c, cls),
                                  f"{cls} posterior, label-free: each engine's four vibration lines, frequency in Hz "
                                  f"against amplitude in mm, medians with 5-95% intervals, and the class reference's "
                                  "line frequencies"))
        out.append(_acquisition_compare(c))
        unid = [p for p, ok in (d.get("identified") or {}).items() if not ok]
        body = _lines_table(c)
        if unid:
            body += (f"<p class='note'>Parameters that stay near their prior (posterior sd over "
                     f"{fmt(d.get('identified_ratio', 0.5), 1)} x prior sd): {w.esc(', '.join(unid))}.</p>")
        corner = c.get("corner")
        if corner and Path(corner).is_file():
            rel = os.path.relpath(corner, report_dir)
            body += (f"<p>Full corner plot (every sampled parameter, per engine, in physical units): "
                     f"<a href='{html.escape(rel)}'>{html.escape(rel)}</a> (opens at full size).</p>"
                     + img(corner, f"{cls} corner plot of the sampled parameters"))
        trace = c.get("trace")
        if trace and Path(trace).is_file():
            body += ("<p>The walkers' paths (burn-in shaded):</p>"
                     + img(trace, f"{cls} trace plot of the walkers' paths"))
        out.append(details(f"{cls}: the lines in numbers, the corner and trace plots", body))
    return "\n".join(out)


def choice_section(r: dict, figs: Figures, w: Html) -> str:
    from . import figures

    sel = r["selection"]["set"]
    test = main_test(r)
    intro = (f"<p>Every choice is made on the selection set '{w.esc(sel)}' ({w.esc(r['selection']['what'])}), "
             "never on a test set, by <b>balanced accuracy</b> (the mean of the class recalls, which an imbalanced "
             "set cannot flatter): each strategy's setting by the mean balanced accuracy of the fast classifiers "
             "trained on it, the best strategy by its CNN's balanced accuracy.</p>")
    rows = []
    for n, c in r["choice"].items():
        scores = c.get("scores") or {}
        score_text = ", ".join(f"{float(v):g}: {s:.2f}" for v, s in scores.items())
        label = figures.PARAM_LABEL.get(c.get("parameter"), c.get("parameter") or "–")
        rows.append([td(w.esc(n), False), td(w.esc(label), False),
                     td(w.num(f"choice.{n}.value", c.get("value"), 2)), td(w.esc(score_text) or "–", False),
                     td(w.esc(c.get("rule", "")), False)])
    out = [intro]
    if rows:
        out.append(table(["strategy", "setting", "chosen", "mean balanced accuracy on the selection set",
                          "rule"], rows))
    if any(c.get("parameter") == "width" for c in r["choice"].values()):
        out.append("<p>The specimen width says how much other drones of a class differ from the calibrated one. "
                   "Only a selection set of other specimens can show that; a set of the calibration drones' own "
                   "acquisitions (the simulated study's 'select') has no specimen variation, so on it the width "
                   "is chosen blind to what it models.</p>")
    best = r.get("best_strategy") or {}
    if best.get("name"):
        sc = best.get("scores") or {}
        top = sc.get(best["name"])
        tied = [n for n, v in sc.items() if n != best["name"] and top is not None and abs(v - top) < 1e-9]
        name = best["name"]
        out.append(f"<p>Best strategy: <b>{w.esc(name)}</b>, CNN balanced accuracy "
                   f"{w.num(f'best_strategy.scores.{name}', top, 2)} on "
                   f"'{w.esc(best.get('set', sel))}'"
                   + (f" (tied with {w.esc(_list(tied))}; the tie goes to the first in the study's order)"
                      if tied else "")
                   + ".</p>")
    peek = r.get("published_peeking_choice")
    if peek and peek.get("value") is not None:
        out.append(f"<p>The published way picks sigma_P on the test set itself ('{w.esc(peek['set'])}'): it would "
                   f"choose sigma_P = {w.num('published_peeking_choice.value', peek['value'], 2)}. It is recorded "
                   "here for comparison and <b>not used</b>: a choice that has seen the test set makes its score "
                   "optimistic.</p>")
    fig = figures.sweeps_figure(r, test)
    if fig is not None:
        out.append("<h3>The sweeps</h3>")
        out.append(figs.embed("sweeps", fig, "Balanced accuracy of the fast classifiers against sigma_P and the "
                              "specimen width, on the selection set (the choice) and the test set (information)"))
        rows = []
        for i, row in enumerate(r["candidates"]["rows"]):
            k = f"candidates.rows.{i}"
            rows.append([td(w.esc(row["strategy"]), False), td(w.num(f"{k}.value", row["value"], 2)),
                         td(w.esc(row["model"]), False), td(w.esc(row["set"]), False),
                         td(w.val_ci(f"{k}.balanced_accuracy", row["balanced_accuracy"], f"{k}.balanced_ci",
                                     row.get("balanced_ci"), br=True)),
                         td(w.num(f"{k}.accuracy", row["accuracy"], decimals(row.get("balanced_ci")))),
                         td(w.num(f"{k}.min_recall", row["min_recall"], 2)),
                         td(w.num(f"{k}.train_seconds", row["train_seconds"], 2))])
        out.append(details("Every candidate in numbers",
                           table(["strategy", "value", "model", "set", "balanced accuracy", "accuracy",
                                  "lowest class recall", "training (s)"], rows)))
    return "\n".join(out)


def speed_section(r: dict, figs: Figures, w: Html) -> str:
    from . import figures

    test = main_test(r)
    out = ["<p class='note'>Each stage's cost against its error, measured in this run on 1 thread: the "
           "generator f(x) (float32 against float64), the marginal likelihood (Monte Carlo error against the "
           "number of simulated acquisitions), the calibration (Monte Carlo error of posterior means against "
           "sampling time), the chain path (reduced against literal computation) and the training of each "
           "classifier (its error on the test set against training time).</p>",
           figs.embed("speed", figures.speed_figure(r, test),
                      "Speed against error of every stage: generator, likelihood, calibration, chain path, training")]
    rows = []
    for i, row in enumerate((r.get("speed") or {}).get("rows") or []):
        rows.append([td(w.esc(row["stage"]), False), td(w.esc(row["setting"]), False), td(w.esc(row["rate"])),
                     td(f'<span data-key="speed.rows.{i}.error">{fmt_sig(row["error"])}</span>'),
                     td(w.esc(row["error_metric"]), False)])
    for cls, c in r["calibration"].items():
        d = c["diagnostics"]
        k = f"calibration.{cls}.diagnostics"
        ess = d.get("ess_min")
        chain = w.num(k + ".steps_over_tau", d.get("steps_over_tau"), 1)
        rows.append([td("calibration", False), td(f"{w.esc(cls)}, chain = {chain} x max tau", False),
                     td(f"{w.num(k + '.seconds', d.get('seconds'), 0)} s"),
                     td(fmt_sig(1 / np.sqrt(ess)) if ess else "–"),
                     td("Monte Carlo error of posterior means, in posterior sd (1/sqrt(min ESS))", False)])
    if test:
        for name, s in r["strategies"].items():
            m = s["tests"].get(test)
            if m is None:
                continue
            rows.append([td("training", False), td(f"CNN {w.esc(name)}", False),
                         td(f"{w.num(f'strategies.{name}.train_seconds', s['train_seconds'], 1)} s"),
                         td(fmt(1 - m["balanced_accuracy"], decimals(m["ci"].get("balanced_accuracy")))),
                         td(f"1 - balanced accuracy on '{w.esc(test)}'", False)])
    out.append(details("Speed against error in numbers",
                       table(["stage", "setting", "speed", "error", "error metric"], rows)))
    return "\n".join(out)


def _plain(v) -> str:
    """A config value as text (lists joined, mappings as 'key value', no repr)."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_plain(x)}" for k, x in v.items()) or "–"
    if isinstance(v, (list, tuple)):
        return ", ".join(_plain(x) for x in v) or "–"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _flatten(d: dict) -> list[tuple[str, object]]:
    """Config rows: the sections (data, simulation, protocol) one level deep."""
    out = []
    for k, v in d.items():
        if k in ("data", "simulation", "protocol") and isinstance(v, dict):
            out += [(f"{k}.{kk}", vv) for kk, vv in v.items()]
        else:
            out.append((k, v))
    return out


def details_section(r: dict, w: Html) -> str:
    rows = [[td(w.esc(n), False), td(str(d["n"])), td(w.esc(_plain(d.get("per_class"))), False)]
            for n, d in r["data"].items()]
    data = table(["set", "acquisitions", "per class"], rows)
    acq = table(["setting", "value"], [[td(w.esc(k), False), td(w.esc(_plain(v)), False)]
                                      for k, v in r["acquisition"].items()])
    cfg = table(["setting", "value"], [[td(w.esc(k), False), td(w.esc(_plain(v)), False)]
                                      for k, v in _flatten(r["config"])])
    tim = table(["stage", "seconds", "resumed from cache"],
                [[td(w.esc(k), False), td(w.num(f"timings.{k}", v, 1)),
                  td("yes" if k in r.get("resumed_stages", []) else "no")]
                 for k, v in (r.get("timings") or {}).items()])
    return (details("Data sets", data) + details(f"Acquisition: {r['acquisition_text']}", acq)
            + details("Configuration", cfg)
            + details(_timings_title(r), tim))


def _timings_title(r: dict) -> str:
    """'Stage timings (...)': the stages' own seconds (a resumed stage keeps the time it took
    when it ran) and, after a resume, this invocation's wall time beside them."""
    stages = sum((r.get("timings") or {}).values())
    resumed = len(r.get("resumed_stages") or [])
    if not resumed:
        return f"Stage timings (total {fmt(stages, 0)} s)"
    return (f"Stage timings (stages {fmt(stages, 0)} s; this run {fmt(r.get('total_seconds'), 0)} s, "
            f"{resumed} stage(s) resumed from the cache)")


def write_report(results: dict, path) -> Path:
    """Write the report of a finished study to ``path`` (atomic); its figures go to
    ``figures/report_*.png`` beside it (and are embedded)."""
    path = Path(path)
    w = Html()
    figs = Figures(path.parent / "figures")
    sentences = finding(results, w)
    toc = "".join(f"<a href='#{sid}'>{t}</a>" for sid, t in (
        ("strategies", "Strategies"), ("calibration", "Calibration"), ("choice", "Choices and sweeps"),
        ("profiles", "Profiles"), ("speed", "Speed"), ("details", "Run details")))
    body = [
        section("finding", "Finding", f"<p class='headline' id='headline'>{' '.join(sentences)}</p>"
                f"<p class='note'>{context(results, w)}</p><nav>{toc}</nav>"),
        section("strategies", "Strategies on new drones", strategies_section(results, figs, w)),
        section("calibration", "Calibration", calibration_section(results, figs, w, path.parent)),
        section("choice", "Choices (made without the test sets) and the sweeps", choice_section(results, figs, w)),
        section("profiles", "Measured against synthetic profiles",
                "<p class='note'>The new drones' measured profiles beside each model-based strategy's profiles at "
                "its chosen setting (tsaug's are distorted copies of the calibration measurements and are not "
                "shown).</p>"
                + img(results.get("profiles_figure"), "Measured and synthetic range profiles per class: median "
                      "and 10-90% band against range from the target in metres")),
        section("speed", "Speed against error", speed_section(results, figs, w)),
        section("details", "Run details", details_section(results, w)),
    ]
    doc = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>mdaug study report</title>"
           f"<meta name='viewport' content='width=device-width, initial-scale=1'><style>{CSS}</style></head><body>"
           f"<h1>mdaug study: which augmentation classifies new drones</h1>{''.join(body)}</body></html>")
    return atomic_write(path, lambda fh: fh.write(doc.encode()))
