"""The finding: a few sentences written from the verdicts of :func:`.verdicts.judge`
(never computed here), and the context line under it (data, acquisition, the command
as it was run, caveats).

Sentence 1: the choice on new drones (or the tie the selection set could not break)
and its score, against the next best strategy. Sentence 2: against tsaug and the
ceiling. Sentence 3: every label the table shows (biased, degenerate, not better or
worse than chance), by strategy.
"""
from __future__ import annotations

from ..inference.result.status import calibration_status
from .markup import Html
from .numbers import decimals, join, signed, spread
from .verdicts import TIE, comparison, judge


def _score(results: dict, w, name: str, test: str, ceiling: bool = False) -> str:
    """'0.70 [0.61, 0.78], runs 0.68–0.72' of a strategy (or the ceiling's model) on ``test``."""
    base = f"ceiling.models.{name}" if ceiling else f"strategies.{name}"
    m = ((results["ceiling"]["models"] if ceiling else results["strategies"])[name])["tests"][test]
    ci = (m.get("ci") or {}).get("balanced_accuracy")
    text = w.val_ci(f"{base}.tests.{test}.balanced_accuracy", m["balanced_accuracy"],
                    f"{base}.tests.{test}.ci.balanced_accuracy", ci)
    if (m.get("n_runs") or 1) > 1:
        text += f", runs {spread(m.get('seed_spread'), decimals(ci))}"
    return text


def _diff(c: dict) -> str:
    return f"{signed(c['difference'], c['ci'])}"


def _against(results, w, names: list[str], b: str, test: str, b_text: str) -> str:
    """'against B (score), a is better: +0.1 [...] and c is level: ...' (b_text once, however
    many strategies are compared with it); '' where no comparison was made."""
    cs = [(a, comparison(results, test, a, b)) for a in names]
    words = [f"{w.esc(a)} is {c['word']}: {_diff(c)}" for a, c in cs if c is not None]
    return f"against {b_text}, {join(words)}" if words else ""


def finding(results: dict, w=Html(), j: dict | None = None) -> list[str]:
    """The finding's sentences (markup of writer ``w``)."""
    j = j or judge(results)
    test, best = j["test"], j["best"]
    tied = list(best.get("tied") or ([best["name"]] if best.get("name") else []))
    if test is None or not tied:
        return ["No strategy could be ranked: the study has no test set or no strategy scored on the selection set."]
    entry = j["sets"][test]
    verdicts = entry["results"]
    strategies = results["strategies"]
    counts = entry["counts"]
    what = "new drones" if test.startswith("new") else f"the '{w.esc(test)}' set"
    where = (f"On {what} (the '{w.esc(test)}' set of {sum(counts.values())} acquisitions, "
             f"{join([f'{n} {c}' for c, n in counts.items()])})")
    sel = w.esc(j["selection"])
    if len(tied) == 1:
        chosen = f"the strategy chosen without the test set, {w.b(tied[0])},"
    else:
        top = best["scores"][tied[0]]
        chosen = (f"the selection set '{sel}' does not separate {join([w.b(n) for n in tied])} (tied: mean "
                  f"balanced accuracy within {TIE} of the best, {top:.2f}; a tie is reported, not broken), which")
    scores = join([f"{w.esc(n)} {_score(results, w, n, test)}" for n in tied]) if len(tied) > 1 else \
        _score(results, w, tied[0], test)
    below = [n for n, v in verdicts.items() if v["chance"] == "worse than chance"]
    if all(v["chance"] for v in verdicts.values()):
        s1 = (f"{where}, no strategy's CNN is better than chance: every balanced-accuracy interval contains 0.5"
              + (f" or lies below it ({join([w.esc(n) for n in below])}: worse than chance)" if below else "")
              + f"; {chosen} {'score' if len(tied) > 1 else 'scores'} {scores}.")
    else:
        s1 = f"{where}, {chosen} {'give CNNs with balanced accuracy' if len(tied) > 1 else 'gives a CNN with balanced accuracy'} {scores}"
        large = [t for t in strategies[tied[0]]["tests"] if t != test and t.startswith(test)]
        if large and len(tied) == 1:  # the same kind of drones, more of them: a tighter interval
            t2 = large[0]
            s1 += (f" (on the larger '{w.esc(t2)}' set of {strategies[tied[0]]['tests'][t2]['n']}: "
                   f"{_score(results, w, tied[0], t2)})")
        others = [n for n in verdicts if n not in tied and not verdicts[n]["degenerate"] and not verdicts[n]["chance"]]
        nxt = max(others, key=lambda n: strategies[n]["tests"][test]["balanced_accuracy"]) if others else None
        if nxt is None:
            s1 += "; every other strategy is degenerate or not better than chance."
        elif comparison(results, test, tied[0], nxt) is None:  # results without paired comparisons
            s1 += "."
        elif len(tied) == 1:
            c = comparison(results, test, tied[0], nxt)
            s1 += (f"; against the best of the others on this set, {w.esc(nxt)} ({_score(results, w, nxt, test)}), "
                   f"it is {c['word']}: {_diff(c)}")
            if c["word"] == "worse":
                s1 += f" ({w.esc(nxt)} was not the choice made on the selection set)"
            s1 += "."
        else:
            c = comparison(results, test, tied[0], tied[1])
            s1 += f"; {w.esc(tied[0])} minus {w.esc(tied[1])}: {_diff(c)}, {c['word']}." if c else "."
    sentences = [s1]
    parts = []
    if "tsaug" in strategies and test in strategies["tsaug"]["tests"]:
        parts.append(_against(results, w, [n for n in tied if n != "tsaug"], "tsaug", test,
                              f"tsaug ({_score(results, w, 'tsaug', test)})"))
    ceil = j.get("ceiling")
    if ceil:
        model = ceil["model"]
        how = (f"{w.esc(model)} trained on the simulator's own data, chosen on the selection set"
               + (f" among the tied {join(ceil['tied'])}" if len(ceil["tied"]) > 1 else "") + ", "
               + _score(results, w, model, test, ceiling=True))
        if ceil["at_chance"]:
            parts.append(w.warn("the ceiling itself is " + j["sets"][test]["ceiling"]["chance"]) + f" ({how}): this "
                         "acquisition leaves its classifier nothing to learn on this set, so no strategy's score "
                         "can be read against it")
        else:
            parts.append(_against(results, w, tied, f"ceiling:{model}", test,
                                  f"the ceiling of the simulated scene ({how})"))
    parts = [p for p in parts if p]
    if parts:
        text = "; ".join(parts)
        sentences.append(text[0].upper() + text[1:] + " (differences in mean balanced accuracy, paired: the same "
                         "test resamples and training runs; better / worse: a 95% interval above / below 0, "
                         "level: one containing 0).")
    sentences.append(labels_sentence(verdicts, w))
    return sentences


def labels_sentence(verdicts: dict, w=Html()) -> str:
    """Every label of the table's verdict column, by strategy."""
    biased, chance, worse, partly = {}, [], [], []
    for n, v in verdicts.items():
        if v["biased_towards"]:
            biased.setdefault(v["biased_towards"], []).append(w.esc(n) + (" (degenerate)" if v["degenerate"] else ""))
        if v["chance"] == "not better than chance":
            chance.append(w.esc(n))
        elif v["chance"] == "worse than chance":
            worse.append(w.esc(n))
        if v.get("degenerate_runs"):
            partly.append(w.esc(n))
    if biased:
        s = ("Biased (a class never recognised, or class recalls whose intervals do not overlap): "
             + "; ".join(f"{join(v)} towards {c}" for c, v in biased.items()))
    else:
        s = "No strategy is biased towards one class beyond its intervals"
    if chance:
        s += f"; not better than chance (a balanced-accuracy interval containing 0.5): {join(chance)}"
    if worse:
        s += f"; worse than chance (an interval below 0.5): {join(worse)}"
    if partly:
        s += f"; a class missed by some of the training runs: {join(partly)}"
    return s + "."


def command(results: dict) -> str:
    """The ``mdaug run`` command that reproduces these results in ``mdaug-study`` (the
    README quotes it; the config file when one was used)."""
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


def context(results: dict, w=Html(), j: dict | None = None) -> str:
    """What the finding is about: the data, the acquisition, the command as it was run,
    the statistics, and the caveats (calibration, measured nuisances)."""
    j = j or judge(results)
    what = ("All measurements are <b>simulated</b> by mdaug's scene simulator (new drones: other specimens "
            "of each class)." if results["simulated"] else "Measured data from the files of the study config.")
    cfg = results["config"]
    runs = cfg["protocol"].get("cnn_seeds", 1)
    text = (f"{what} Acquisition: {w.esc(results['acquisition_text'])}. Seed {cfg['seed']}"
            f"{', quick sizes' if cfg.get('quick') else ''}; run as <code>{w.esc(results.get('invocation') or command(results))}"
            f"</code>. Each CNN is trained {runs} times (seeds); its figure is the mean over the runs and its 95% "
            "interval covers the test sample and the training runs (a bootstrap of the test set's drones, where "
            "it says which drone made each acquisition, and then their acquisitions, one run picked at random in "
            "each resample: where one training run scores on a test sample like this one).")
    for c, cal in results["calibration"].items():
        st = calibration_status(cal)
        if not st.trusted:
            text += (f" {w.warn(f'Calibration of {w.esc(c)}: {w.esc(st.headline)}')} (see Calibration): the posterior-based "
                     "strategies rest on it.")
    for f in j["nuisances"]:
        d, u = f["digits"], f["unit"]
        text += (" " + w.warn(f"{f['class']}: the measured {f['what']} ({f['measured'][0]:.{d}f} to "
                              f"{f['measured'][1]:.{d}f} {u}) lies far outside the acquisition's stated "
                              f"{f['stated'][0]:.{d}f} to {f['stated'][1]:.{d}f} {u}") + ".")
    return text
