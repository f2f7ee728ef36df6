"""Every verdict of the study, computed in this one place: the study's choices (the
best strategy, the ceiling model), each result's labels and each comparison's word.
The report's finding, its tables and the README's section are all written from
:func:`judge` (their wording lives in :mod:`.finding` and :func:`label`), so a sentence
and a table cell cannot disagree.

The rules:

* **degenerate**: a class that no training run recognises (its recall 0 in every
  run); a class missed by some runs only is said so ("in 1 of 3 runs"); the rule is
  :func:`mdaug.classify.metrics.degenerate` (the verbs train, evaluate and baseline
  apply the same one);
* **worse than chance**: a balanced-accuracy interval entirely below 0.5; **not better
  than chance**: an interval that contains 0.5;
* **majority**: an accuracy no better than always answering the commonest class of
  an imbalanced set;
* **biased towards C**: a degenerate result, or class recalls whose intervals do not
  overlap (C the class with the higher recall);
* **better / worse / level**: a paired difference in mean balanced accuracy whose
  95% interval lies above 0 / below 0 / contains 0;
* **ties**: on the selection set, results whose mean balanced accuracy is within
  :data:`TIE` of the best are tied (the one rule, :func:`mdaug.classify.protocol.choose`); tied strategies are reported as tied (none of
  them is "the" choice); the ceiling's model among tied ones goes to the CNN (like for
  like with the strategies' CNNs), then by :data:`CEILING_ORDER`;
* **ceiling at chance**: the chosen ceiling model's balanced-accuracy interval on the
  test set contains 0.5 (or lies below): the acquisition leaves nothing to learn there;
* **nuisance far outside**: a level the calibration measured (the carrier return, the
  noise floor: the range of the measurements' posterior medians) beyond the
  acquisition's stated range by more than :data:`FAR` of that range's width.
"""
from __future__ import annotations

import numpy as np

from ..classify.metrics import degenerate, degenerate_words
from ..classify.protocol import PREFER, TIE, choose, ties

CHANCE = 0.5
FAR = 0.5
CEILING_ORDER = ("cnn", "svm", "xgb", "nb")
NUISANCES = (("carrier", "carrier return", "x sum(Gamma)", 2), ("noise_db", "noise floor", "dB", 0))
TIE_RULE = (f"mean balanced accuracy over the training runs; results within {TIE} of the best are tied and "
            "reported together")
CEILING_RULE = (f"the model with the best mean balanced accuracy on the selection set; ties within {TIE} go to "
                "the CNN (like for like with the strategies), then in the order " + ", ".join(CEILING_ORDER))


# ---- one result -------------------------------------------------------------------------------------
def counts(results: dict, test: str, m: dict | None = None) -> dict:
    """{class: count} of a set (from the data index, else from a metrics dict)."""
    d = (results.get("data") or {}).get(test)
    if d and d.get("per_class"):
        return {c: int(n) for c, n in d["per_class"].items()}
    return {c: int(v["n"]) for c, v in (m or {}).get("per_class", {}).items()}


def majority(results: dict, test: str, m: dict | None = None):
    """(class, accuracy of always answering it) of an imbalanced set; None if balanced."""
    c = counts(results, test, m)
    n = sum(c.values())
    if not n or len(set(c.values())) <= 1:
        return None
    cls = max(c, key=c.get)
    return cls, c[cls] / n


def chance(interval) -> str | None:
    if not interval:
        return None
    if interval[1] < CHANCE:
        return "worse than chance"
    if interval[0] <= CHANCE:
        return "not better than chance"
    return None


def result(m: dict, classes, always=None) -> dict:
    """The labels of one result (metrics of :func:`mdaug.classify.metrics.evaluate_runs`)."""
    recalls = {c: (m["per_class"].get(c) or {}).get("recall") for c in classes}
    ci = m.get("ci") or {}
    out = {**degenerate(m, classes), "chance": chance(ci.get("balanced_accuracy")), "below_majority": None,
           "biased_towards": None}
    zero = out["zero_recall"]
    if always is not None and m["accuracy"] <= always[1] + 1e-12:
        out["below_majority"] = list(always)
    rc = {c: ((ci.get("per_class") or {}).get(c) or {}).get("recall") for c in classes}
    known = {c: r for c, r in recalls.items() if r is not None}
    if len(known) >= 2:
        top, bottom = max(known, key=known.get), min(known, key=known.get)
        if top != bottom and (zero or (rc.get(top) and rc.get(bottom) and rc[top][0] > rc[bottom][1])):
            out["biased_towards"] = top
    return out


def label(v: dict) -> str:
    """A result's verdicts as the short text of a table cell ('' when there is nothing to say)."""
    words = degenerate_words(v)
    parts = words[:1] if v["degenerate"] else []
    if not v["degenerate"] and v["biased_towards"]:
        parts.append(f"biased towards {v['biased_towards']}")
    parts += words[1:] if v["degenerate"] else words
    if v["chance"]:
        parts.append(v["chance"])
    if v["below_majority"]:
        cls, acc = v["below_majority"]
        parts.append(f"accuracy no better than always answering {cls} ({acc:.2f})")
    return "; ".join(parts)


# ---- comparisons and choices -----------------------------------------------------------------------
def word(ci) -> str:
    """'better', 'worse' or 'level': where a difference's interval lies against 0."""
    if ci is None:
        return "level"
    return "better" if ci[0] > 0 else "worse" if ci[1] < 0 else "level"


def comparison(results: dict, test: str, a: str, b: str) -> dict | None:
    """The paired difference A - B on ``test`` with its word (ceiling models: 'ceiling:<model>')."""
    d = ((results.get("comparisons") or {}).get(test) or {}).get(f"{a}|{b}")
    if d is None:
        return None
    return {"a": a, "b": b, "difference": d["difference"], "ci": d["ci"], "word": word(d["ci"])}


def choose_setting(rows: list[dict], strategy: str, param: str | None, on: str) -> dict:
    """The value of ``strategy``'s setting with the best mean balanced accuracy (over the
    fast classifiers) on set ``on``, by the one choice rule
    (:func:`mdaug.classify.protocol.choose`: values within :data:`TIE` of it are tied,
    the tie goes to the smaller sigma_P, the larger width; stated in ``rule``)."""
    by_value: dict[float, list[float]] = {}
    for r in rows:
        if r["strategy"] == strategy and r["test_set"] == on:
            by_value.setdefault(float(r["value"]), []).append(r["balanced_accuracy"])
    if not by_value:
        return {"value": None, "set": on, "scores": {}}
    means = {v: float(np.mean(s)) for v, s in sorted(by_value.items())}
    value, tied = choose(means, PREFER.get(param), TIE)
    return {"value": value, "parameter": param, "set": on, "scores": means, "tied": tied,
            "rule": f"best mean balanced accuracy of {', '.join(sorted({r['model'] for r in rows}))}; ties within "
                    f"{TIE} to the {PREFER.get(param)} {param}"}


def best_strategy(strategies: dict, on: str) -> dict:
    """The strategy (strategies) with the best mean balanced accuracy on set ``on``;
    ``name`` is None when several are tied (``tied`` lists them)."""
    scores = {n: s["tests"][on]["balanced_accuracy"] for n, s in strategies.items() if on in s["tests"]}
    tied = ties(scores)
    return {"name": tied[0] if len(tied) == 1 else None, "tied": tied, "set": on, "scores": scores,
            "rule": TIE_RULE}


def ceiling_choice(models: dict, on: str) -> dict | None:
    """The ceiling's model, chosen on set ``on`` (never a test set) by :data:`CEILING_RULE`."""
    scores = {n: m["tests"][on]["balanced_accuracy"] for n, m in models.items() if on in m["tests"]}
    tied = ties(scores)
    if not tied:
        return None
    order = [n for n in CEILING_ORDER if n in tied] + [n for n in tied if n not in CEILING_ORDER]
    return {"model": order[0], "tied": tied, "set": on, "scores": scores, "rule": CEILING_RULE}


# ---- the acquisition -----------------------------------------------------------------------------------
def nuisances(calibration: dict) -> list[dict]:
    """Measured carrier and noise levels far outside the acquisition's stated ranges."""
    out = []
    for cls, cal in (calibration or {}).items():
        st, me = cal.get("acquisition") or {}, cal.get("measured_acquisition") or {}
        for key, what, unit, d in NUISANCES:
            if not st.get(key) or not me.get(key):
                continue
            lo, hi = st[key]
            margin = FAR * (hi - lo)
            if me[key][0] < lo - margin or me[key][1] > hi + margin:
                out.append({"class": cls, "key": key, "what": what, "unit": unit, "digits": d,
                            "measured": list(me[key]), "stated": [lo, hi]})
    return out


# ---- everything ---------------------------------------------------------------------------------------------
def test_sets(results: dict) -> list[str]:
    sel = results["selection"]["set"]
    return list(dict.fromkeys(t for s in results["strategies"].values() for t in s["tests"] if t != sel))


def main_test(results: dict) -> str | None:
    """The test set the finding is about: 'new' (new drones) when there is one."""
    names = test_sets(results)
    if not names:
        return None
    return "new" if "new" in names else names[0]


def ceiling_test(results: dict, test: str) -> dict | None:
    """The chosen ceiling model's record on ``test`` (None where there is none)."""
    ceiling = results.get("ceiling") or {}
    chosen = (ceiling.get("chosen") or {}).get("model")
    return ((ceiling.get("models") or {}).get(chosen) or {}).get("tests", {}).get(test)


def judge(results: dict) -> dict:
    """Every verdict of a study's results: {test, selection, sets: {set: {counts, majority,
    results: {strategy: verdicts}, ceiling: verdicts}}, best, ceiling, nuisances}."""
    classes = list(results["config"]["classes"])
    sel = results["selection"]["set"]
    test = main_test(results)
    ceiling = results.get("ceiling") or {}
    chosen = ceiling.get("chosen")
    sets = {}
    for t in [*test_sets(results), sel]:
        always = majority(results, t)
        entry = {"counts": counts(results, t), "majority": always,
                 "results": {n: result(s["tests"][t], classes, always)
                             for n, s in results["strategies"].items() if t in s["tests"]}}
        cm = ceiling_test(results, t)
        entry["ceiling"] = result(cm, classes, always) if cm else None
        sets[t] = entry
    best = results.get("best_strategy") or {}
    ceil = None
    if chosen:
        v = sets.get(test, {}).get("ceiling") if test else None
        ceil = {**chosen, "at_chance": bool(v and v["chance"])}
    return {"test": test, "selection": sel, "sets": sets, "best": best, "ceiling": ceil,
            "nuisances": nuisances(results.get("calibration"))}
