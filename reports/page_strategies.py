"""The report's "Strategies on new drones" section: the figure, the table of every
strategy's CNN (mean over its training runs, interval, the runs' spread, verdicts from
:func:`.verdicts.judge`), the same on every other set, the confusion matrices and the
ceiling."""
from __future__ import annotations

import html

import numpy as np

from . import figures
from .markup import Figures, Html, details, table, td
from .numbers import decimals, join, spread
from .verdicts import label, test_sets


def setting_text(results: dict, name: str) -> str:
    s = results["strategies"][name]
    for key, text in (("sigma_p", "sigma_P"), ("width", "width")):
        if s.get(key) is not None:
            return f"{text} = {s[key]:g}"
    return "–"


def chosen(j: dict) -> list[str]:
    """The strategy chosen on the selection set, or the strategies tied there."""
    best = j["best"]
    return list(best.get("tied") or ([best["name"]] if best.get("name") else []))


def choice_mark(j: dict, name: str) -> str:
    names = chosen(j)
    if name not in names:
        return ""
    return " (chosen)" if len(names) == 1 else " (tied choice)"


def metric_cells(w: Html, base: str, m: dict, classes, precision: bool = True, runs: bool = True) -> list[str]:
    ci = m.get("ci") or {}
    bal_ci = ci.get("balanced_accuracy")
    cells = [td(w.val_ci(f"{base}.balanced_accuracy", m["balanced_accuracy"], f"{base}.ci.balanced_accuracy",
                         bal_ci, br=True))]
    if runs:
        s = spread(m.get("seed_spread"), decimals(bal_ci)) if (m.get("n_runs") or 1) > 1 else ""
        cells.append(td(f"{s}<br><span class='ci'>{m.get('n_runs') or 1} runs</span>" if s else "1 run"))
    cells.append(td(w.val_ci(f"{base}.accuracy", m["accuracy"], f"{base}.ci.accuracy", ci.get("accuracy"), br=True)))
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
            if j is None or cm[:, j].sum() == 0 or pc.get("precision") is None:  # never predicted: undefined
                cells.append(td("–"))
                continue
            cell = w.val_ci(f"{base}.per_class.{c}.precision", pc.get("precision"),
                            f"{base}.ci.per_class.{c}.precision", cc.get("precision"), br=True)
            defined, runs_ = pc.get("precision_runs"), m.get("n_runs") or 1
            if defined is not None and defined < runs_:  # the mean is over the runs that predict the class
                cell += f"<br><span class='ci'>over the {defined} of {runs_} runs that predict {c}</span>"
            cells.append(td(cell))
    return cells


def strategy_table(r: dict, j: dict, test: str, w: Html) -> str:
    """Every strategy's CNN on set ``test``: the metrics with intervals and the runs' spread,
    the selection set's balanced accuracy (the ranking) and the verdicts."""
    classes = list(r["config"]["classes"])
    sel = r["selection"]["set"]
    verdicts = j["sets"][test]["results"]
    head = (["strategy<br><span class='ci'>setting</span>", "balanced accuracy",
             "runs: lowest–highest balanced accuracy", "accuracy"]
            + [f"recall {c}" for c in classes] + [f"precision {c}" for c in classes]
            + ([f"balanced accuracy on '{html.escape(sel)}' (the selection set)"] if test != sel else [])
            + ["verdict"])
    rows, cls = [], []
    for name, s in r["strategies"].items():
        if test not in s["tests"]:
            continue
        m = s["tests"][test]
        setting = setting_text(r, name)
        mark = choice_mark(j, name)
        cells = [td(w.esc(name) + (f" <b>{mark.strip()}</b>" if mark else "")
                    + (f"<br><span class='ci'>{w.esc(setting)}</span>" if setting != "–" else ""), False)]
        cells += metric_cells(w, f"strategies.{name}.tests.{test}", m, classes)
        ms = s["tests"].get(sel)
        if test != sel:
            cells.append(td(w.val_ci(f"strategies.{name}.tests.{sel}.balanced_accuracy", ms["balanced_accuracy"],
                                     f"strategies.{name}.tests.{sel}.ci.balanced_accuracy",
                                     (ms.get("ci") or {}).get("balanced_accuracy"), br=True) if ms else "–"))
        v = label(verdicts[name])
        cells.append(f"<td class='verdict'>{f'<span class=flag>{v}</span>' if v else ''}</td>")
        rows.append(cells)
        cls.append("chosen" if mark else "")
    return table(head, rows, cls)


def majority_note(j: dict, test: str) -> str:
    counts = j["sets"][test]["counts"]
    always = j["sets"][test]["majority"]
    per_class = ", ".join(f"{v} {c}" for c, v in counts.items())
    text = f"The '{html.escape(test)}' set holds {sum(counts.values())} acquisitions ({per_class})."
    if always:
        text += (f" It is imbalanced: always answering {always[0]} scores accuracy {always[1]:.2f} (balanced "
                 "accuracy 0.50), so accuracy alone says little; balanced accuracy (the mean of the class recalls) "
                 "is the figure to read.")
    return f"<p class='note'>{text}</p>"


def ceiling_line(r: dict, j: dict, test: str):
    """(label, balanced accuracy, interval) of the chosen ceiling model on ``test``, for the figure."""
    c = j.get("ceiling")
    if not c:
        return None
    m = r["ceiling"]["models"][c["model"]]["tests"].get(test)
    if m is None:
        return None
    return (f"{c['model']} on simulated scenes", m["balanced_accuracy"], (m.get("ci") or {}).get("balanced_accuracy"))


NOTE = ("<p class='note'>Each figure is the mean over the CNN's training runs (seeds). Intervals: 95%, covering "
        "the test sample and the training runs (a bootstrap of the test set's drones, where the set says which "
        "drone made each acquisition, and then their acquisitions; one run picked at random "
        "in each resample: where one training run scores on a test sample like this one; it holds every run's own "
        "score). The same resamples and picks serve every strategy and the ceiling, so their differences "
        "(the finding) are paired. Recall of a class is the share of its acquisitions classified correctly (the "
        "published per-class 'precision'); precision is the share of the acquisitions predicted as the class "
        "that are of it (a dash: no run ever predicts the class, precision is undefined; a mean over fewer runs "
        "than the others says over how many: the runs that never predict the class are left out, not counted "
        "as 0). Verdicts: "
        "<i>degenerate</i>, a class no run recognises; <i>biased</i>, class recalls whose intervals do not "
        "overlap; <i>not better than chance</i>, a balanced-accuracy interval that contains 0.5; <i>worse than "
        "chance</i>, one below 0.5.</p>")


def strategies_section(r: dict, j: dict, figs: Figures, w: Html) -> str:
    test = j["test"]
    if test is None:
        return "<p>No test set.</p>"
    names = chosen(j)
    out = [figs.embed("strategies", figures.strategies_figure(r, test, names, ceiling_line(r, j, test)),
                      f"Balanced accuracy and per-class recall with 95% intervals of every strategy's CNN on the "
                      f"'{test}' set, with chance and the simulated scene's ceiling as lines"),
           majority_note(j, test), strategy_table(r, j, test, w), NOTE,
           "<ul>" + "".join(f"<li><b>{w.esc(n)}</b>: {w.esc(t)}</li>" for n, t in r["strategy_text"].items())
           + "</ul>"]
    more = [f"<h4>'{w.esc(t)}' set</h4>" + majority_note(j, t) + strategy_table(r, j, t, w)
            for t in test_sets(r) if t != test]
    sel = r["selection"]["set"]
    more.append(f"<h4>Selection set '{w.esc(sel)}' (the choices are made here)</h4>"
                + majority_note(j, sel) + strategy_table(r, j, sel, w))
    out.append(details("Other sets: the same table on every other set", "".join(more)))
    out.append(details(f"Confusion matrices on '{test}'",
                       figs.embed("confusion", figures.confusion_figure(r, test),
                                  f"Confusion matrices of every strategy's CNN on the '{test}' set (summed over its "
                                  "training runs), each titled with its balanced accuracy and 95% interval")))
    if r.get("ceiling"):
        out.append(details("The ceiling: classifiers trained on the simulator's own data", ceiling_table(r, j, w)))
    return "\n".join(out)


def ceiling_table(r: dict, j: dict, w: Html) -> str:
    classes = list(r["config"]["classes"])
    c = r["ceiling"]
    what = c.get("what", "")
    choice = j.get("ceiling") or {}
    rows, marks = [], []
    for model, cm in c["models"].items():
        for t, m in cm["tests"].items():
            mark = model == choice.get("model")
            rows.append([td(w.esc(model) + (" <b>(chosen)</b>" if mark else ""), False), td(w.esc(t), False)]
                        + metric_cells(w, f"ceiling.models.{model}.tests.{t}", m, classes, precision=False)
                        + [td(w.num(f"ceiling.models.{model}.train_seconds", cm["train_seconds"], 2))])
            marks.append("chosen" if mark else "")
    rule = ""
    if choice:
        rule = (f"<p>The ceiling is <b>{w.esc(choice['model'])}</b>, chosen on the selection set "
                f"'{w.esc(choice['set'])}' like every other choice: {w.esc(choice['rule'])}"
                + (f" (tied there: {w.esc(join(choice['tied']))})" if len(choice["tied"]) > 1 else "") + ".</p>")
        if choice.get("at_chance"):
            rule += ("<p class='warn'>The ceiling is not better than chance on the test set: the acquisition "
                     "leaves its classifier nothing to learn there, and no strategy can be read against it.</p>")
    return (f"<p>{w.esc(what[:1].upper() + what[1:])}. No augmentation of a few measurements should beat it: it is "
            "what the acquisition leaves of the class difference.</p>" + rule
            + table(["model", "set", "balanced accuracy", "runs", "accuracy"]
                    + [f"recall {k}" for k in classes] + ["training (s)"], rows, marks))
