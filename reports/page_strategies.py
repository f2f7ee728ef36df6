"""The report's "Strategies on new drones" section: the figure, the table of every
strategy's CNN (mean over its training runs, interval, the runs' spread, verdicts from
:func:`.verdicts.judge`), the same on every other set, the confusion matrices and the
ceiling."""
from __future__ import annotations

import html

import numpy as np

from . import figures
from .markup import Figures, Html, details, table, td
from .numbers import column_decimals, join, spread
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


def _ci(m: dict, column: str):
    """The interval of one metric column of :func:`metric_cells` ('balanced_accuracy',
    'accuracy', 'recall HELI', 'precision QUAD') in metrics ``m``."""
    ci = m.get("ci") or {}
    if " " not in column:
        return ci.get(column)
    what, c = column.split(" ", 1)
    return (((ci.get("per_class") or {}).get(c) or {}).get(what))


def column_digits(ms: list, classes) -> dict:
    """{metric column: decimals} over the metrics ``ms`` of a table's rows: one precision
    rule per column (:func:`.numbers.column_decimals`)."""
    cols = ["balanced_accuracy", "accuracy"] + [f"{w} {c}" for w in ("recall", "precision") for c in classes]
    return {col: column_decimals([_ci(m, col) for m in ms if m]) for col in cols}


def metric_cells(w: Html, base: str, m: dict, classes, precision: bool = True, runs: bool = True,
                 accuracy: bool = True, recall: bool = True, balanced: bool = True, digits: dict | None = None
                 ) -> list[str]:
    """The cells of one result: balanced accuracy, the runs' spread, accuracy, recall and
    precision per class (each optional), at the column's decimals (``digits``, of
    :func:`column_digits`; None: this result's own)."""
    digits = digits or column_digits([m], classes)
    ci = m.get("ci") or {}
    bal_ci = ci.get("balanced_accuracy")
    cells = []
    if balanced:
        cells.append(td(w.val_ci(f"{base}.balanced_accuracy", m["balanced_accuracy"], f"{base}.ci.balanced_accuracy",
                                 bal_ci, d=digits["balanced_accuracy"], br=True)))
    if runs:
        s = spread(m.get("seed_spread"), digits["balanced_accuracy"]) if (m.get("n_runs") or 1) > 1 else ""
        cells.append(td(f"{s}<br><span class='ci'>{m.get('n_runs') or 1} runs</span>" if s else "1 run"))
    if accuracy:
        cells.append(td(w.val_ci(f"{base}.accuracy", m["accuracy"], f"{base}.ci.accuracy", ci.get("accuracy"),
                                 d=digits["accuracy"], br=True)))
    cm = np.asarray(m["confusion_matrix"])
    labels = list(m["labels"])
    for c in classes if recall else []:
        pc = m["per_class"].get(c) or {}
        cells.append(td(w.val_ci(f"{base}.per_class.{c}.recall", pc.get("recall"),
                                 f"{base}.ci.per_class.{c}.recall", _ci(m, f"recall {c}"), d=digits[f"recall {c}"],
                                 br=True)))
    if precision:
        for c in classes:
            pc = m["per_class"].get(c) or {}
            j = labels.index(c) if c in labels else None
            if j is None or cm[:, j].sum() == 0 or pc.get("precision") is None:  # never predicted: undefined
                cells.append(td("–"))
                continue
            cell = w.val_ci(f"{base}.per_class.{c}.precision", pc.get("precision"),
                            f"{base}.ci.per_class.{c}.precision", _ci(m, f"precision {c}"),
                            d=digits[f"precision {c}"], br=True)
            defined, runs_ = pc.get("precision_runs"), m.get("n_runs") or 1
            if defined is not None and defined < runs_:  # the mean is over the runs that predict the class
                cell += f"<br><span class='ci wrap'>over the {defined} of {runs_} runs that predict {c}</span>"
            cells.append(td(cell))
    return cells


def _rows(r: dict, test: str):
    """(name, metrics on ``test``) of every strategy scored on it."""
    return [(name, s["tests"][test]) for name, s in r["strategies"].items() if test in s["tests"]]


def _name_cell(r: dict, j: dict, name: str, w: Html) -> str:
    setting = setting_text(r, name)
    mark = choice_mark(j, name)
    return td(w.esc(name) + (f" <b>{mark.strip()}</b>" if mark else "")
              + (f"<br><span class='ci'>{w.esc(setting)}</span>" if setting != "–" else ""), False)


def strategy_table(r: dict, j: dict, test: str, w: Html) -> str:
    """Every strategy's CNN on set ``test``: balanced accuracy with its interval and the
    runs' spread, the class recalls, the selection set's balanced accuracy (the ranking)
    and the verdicts; accuracy and precision are in :func:`precision_table` (the page
    stays within 1,280 px: tests/test_report_tables.py)."""
    classes = list(r["config"]["classes"])
    sel = r["selection"]["set"]
    verdicts = j["sets"][test]["results"]
    head = (["strategy<br><span class='ci'>setting</span>", "balanced accuracy",
             "runs: lowest – highest balanced accuracy"]
            + [f"recall {c}" for c in classes]
            + ([f"balanced accuracy on '{html.escape(sel)}' (the selection set)"] if test != sel else [])
            + ["verdict"])
    found = _rows(r, test)
    digits = column_digits([m for _, m in found], classes)
    sel_digits = column_decimals([_ci(r["strategies"][n]["tests"].get(sel) or {}, "balanced_accuracy")
                                  for n, _ in found])
    rows, cls = [], []
    for name, m in found:
        cells = [_name_cell(r, j, name, w)]
        cells += metric_cells(w, f"strategies.{name}.tests.{test}", m, classes, precision=False, accuracy=False,
                              digits=digits)
        ms = r["strategies"][name]["tests"].get(sel)
        if test != sel:
            cells.append(td(w.val_ci(f"strategies.{name}.tests.{sel}.balanced_accuracy", ms["balanced_accuracy"],
                                     f"strategies.{name}.tests.{sel}.ci.balanced_accuracy",
                                     (ms.get("ci") or {}).get("balanced_accuracy"), d=sel_digits, br=True)
                            if ms else "–"))
        v = label(verdicts[name])
        cells.append(f"<td class='verdict'>{f'<span class=flag>{v}</span>' if v else ''}</td>")
        rows.append(cells)
        cls.append("chosen" if choice_mark(j, name) else "")
    return table(head, rows, cls)


def precision_table(r: dict, j: dict, test: str, w: Html) -> str:
    """Every strategy's CNN on set ``test``: accuracy and the precision of each class
    (the columns the strategy table leaves out)."""
    classes = list(r["config"]["classes"])
    found = _rows(r, test)
    digits = column_digits([m for _, m in found], classes)
    rows = [[_name_cell(r, j, name, w)]
            + metric_cells(w, f"strategies.{name}.tests.{test}", m, classes, runs=False, recall=False,
                           balanced=False, digits=digits)
            for name, m in found]
    return table(["strategy<br><span class='ci'>setting</span>", "accuracy"]
                 + [f"precision {c}" for c in classes], rows,
                 ["chosen" if choice_mark(j, name) else "" for name, _ in found])


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
           majority_note(j, test), strategy_table(r, j, test, w),
           details(f"Accuracy and precision per class on '{test}'", precision_table(r, j, test, w)), NOTE,
           "<ul>" + "".join(f"<li><b>{w.esc(n)}</b>: {w.esc(t)}</li>" for n, t in r["strategy_text"].items())
           + "</ul>"]
    more = [f"<h4>'{w.esc(t)}' set</h4>" + majority_note(j, t) + strategy_table(r, j, t, w)
            + precision_table(r, j, t, w) for t in test_sets(r) if t != test]
    sel = r["selection"]["set"]
    more.append(f"<h4>Selection set '{w.esc(sel)}' (the choices are made here)</h4>"
                + majority_note(j, sel) + strategy_table(r, j, sel, w) + precision_table(r, j, sel, w))
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
    digits = column_digits([m for cm in c["models"].values() for m in cm["tests"].values()], classes)
    for model, cm in c["models"].items():
        for t, m in cm["tests"].items():
            mark = model == choice.get("model")
            rows.append([td(w.esc(model) + (" <b>(chosen)</b>" if mark else ""), False), td(w.esc(t), False)]
                        + metric_cells(w, f"ceiling.models.{model}.tests.{t}", m, classes, precision=False,
                                       digits=digits)
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
