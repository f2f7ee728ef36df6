"""The report's "Choices" section: every setting chosen on the selection set (never a
test set), the best strategy (or the strategies tied there, with the rule), the
published peeking choice recorded and not used, the sweeps."""
from __future__ import annotations

from ..classify.protocol import row_ci
from . import figures
from .markup import Figures, Html, details, table, td
from .numbers import column_decimals, join


def _best_text(r: dict, j: dict, w: Html, sel: str) -> str:
    best = j["best"]
    tied = list(best.get("tied") or ([best["name"]] if best.get("name") else []))
    if not tied:
        return ""
    sc = best.get("scores") or {}
    where = f"on '{w.esc(best.get('set', sel))}'"
    rule = w.esc(best.get("rule") or "")
    if len(tied) == 1:
        name = tied[0]
        return (f"<p>Best strategy: <b>{w.esc(name)}</b>, CNN mean balanced accuracy "
                f"{w.num(f'best_strategy.scores.{name}', sc.get(name), 2)} {where} (rule: {rule}).</p>")
    scores = join([f"{w.esc(n)} {w.num(f'best_strategy.scores.{n}', sc.get(n), 2)}" for n in tied])
    return (f"<p>Best strategy: a <b>tie</b> {where} between {scores} (rule: {rule}). The selection set cannot "
            "tell them apart, so none of them is the choice: the finding and the tables report each of them.</p>")


def choice_section(r: dict, j: dict, figs: Figures, w: Html) -> str:
    sel = r["selection"]["set"]
    test = j["test"]
    intro = (f"<p>Every choice is made on the selection set '{w.esc(sel)}' ({w.esc(r['selection']['what'])}), "
             "never on a test set, by <b>balanced accuracy</b> (the mean of the class recalls, which an imbalanced "
             "set cannot flatter): each strategy's setting by the mean balanced accuracy of the fast classifiers "
             "trained on it, the best strategy by its CNN's balanced accuracy averaged over the training runs, the "
             "ceiling's model likewise.</p>")
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
    out.append(_best_text(r, j, w, sel))
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
        d = column_decimals([row_ci(row) for row in r["candidates"]["rows"]])  # one precision per column
        for i, row in enumerate(r["candidates"]["rows"]):
            k = f"candidates.rows.{i}"
            rows.append([td(w.esc(row["strategy"]), False), td(w.num(f"{k}.value", row["value"], 2)),
                         td(w.esc(row["model"]), False), td(w.esc(row["test_set"]), False),
                         td(w.val_ci(f"{k}.balanced_accuracy", row["balanced_accuracy"],
                                     (f"{k}.balanced_lo", f"{k}.balanced_hi"), row_ci(row), d=d, br=True)),
                         td(w.num(f"{k}.accuracy", row["accuracy"], d)),
                         td(w.num(f"{k}.min_recall", row["min_recall"], 2)),
                         td(w.num(f"{k}.train_seconds", row["train_seconds"], 2))])
        out.append(details("Every candidate in numbers",
                           table(["strategy", "value", "model", "set", "balanced accuracy", "accuracy",
                                  "lowest class recall", "training (s)"], rows)))
    return "\n".join(out)
