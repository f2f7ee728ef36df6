"""Training runs inside every interval, paired comparisons, and the verdicts in one
place (classify/metrics.py: evaluate_runs, paired_difference; reports/statistics.py,
reports/verdicts.py, reports/finding.py)."""
import copy
import re

import numpy as np
import pytest

from mdaug.classify import evaluate
from mdaug.classify.metrics import evaluate_runs, paired_difference, resample_indices, run_scores, seed_uniforms
from mdaug.reports import statistics, verdicts
from mdaug.reports.finding import finding
from mdaug.reports.markup import Text
from mdaug.reports.readme import check_readme, replace_section, results_section, table_rows, BEGIN, END

CLASSES = ["HELI", "QUAD"]


def _preds(y, recall, rng):
    """Predictions of y with each class recognised at its recall (the rest flipped)."""
    p = y.copy()
    for i, c in enumerate(CLASSES):
        idx = np.flatnonzero(y == c)
        p[rng.choice(idx, size=int(round((1 - recall[i]) * idx.size)), replace=False)] = CLASSES[1 - i]
    return p


# ---- the metrics of several training runs ----------------------------------------------------------
def test_the_interval_holds_every_run_and_the_figure_is_their_mean():
    rng = np.random.default_rng(0)
    y = np.array(["HELI"] * 40 + ["QUAD"] * 60)
    runs = np.stack([_preds(y, (r, 0.8), rng) for r in (0.45, 0.7, 0.95)])  # a wide seed spread
    m = evaluate_runs(y, runs, labels=CLASSES, n_boot=1000, random_state=1, seeds=[5, 6, 7])
    own = [evaluate(y, p, labels=CLASSES, n_boot=0)["balanced_accuracy"] for p in runs]
    assert [r["balanced_accuracy"] for r in m["runs"]] == pytest.approx(own)
    assert m["balanced_accuracy"] == pytest.approx(np.mean(own))
    assert m["seed_spread"]["balanced_accuracy"] == pytest.approx([min(own), max(own)])
    lo, hi = m["ci"]["balanced_accuracy"]
    assert all(lo <= s <= hi for s in own)
    # the test-sample bootstrap of the mean run alone is narrower: the runs widen it
    alone = evaluate(y, runs[1], labels=CLASSES, n_boot=1000, random_state=1)["ci"]["balanced_accuracy"]
    assert hi - lo > alone[1] - alone[0]
    assert m["n_runs"] == 3 and m["seeds"] == [5, 6, 7] and "run picked at random" in m["ci"]["method"]
    assert np.asarray(m["confusion_matrix"]).sum() == 3 * y.size


def test_one_run_is_the_ordinary_bootstrap():
    rng = np.random.default_rng(1)
    y = np.array(["HELI"] * 30 + ["QUAD"] * 50)
    p = _preds(y, (0.6, 0.9), rng)
    idx = resample_indices(y.size, 500, 3)
    m = evaluate_runs(y, p[None], labels=CLASSES, n_boot=500, resamples=idx)
    plain = evaluate(y, p, labels=CLASSES, n_boot=0)
    for k in ("accuracy", "balanced_accuracy"):
        assert m[k] == pytest.approx(plain[k])
    bal = run_scores(y, p[None], CLASSES, idx)[0]
    assert m["ci"]["balanced_accuracy"] == pytest.approx(list(np.percentile(bal, [2.5, 97.5])))


def test_paired_differences_of_identical_predictions_are_exactly_zero():
    rng = np.random.default_rng(2)
    y = np.array(["HELI"] * 30 + ["QUAD"] * 50)
    runs = np.stack([_preds(y, (0.7, 0.8), rng) for _ in range(3)])
    idx, u = resample_indices(y.size, 400, 0), seed_uniforms(400, 3, 0)
    sc = run_scores(y, runs, CLASSES, idx)
    point = run_scores(y, runs, CLASSES, np.arange(y.size)[None])[:, 0]
    d = paired_difference(point, point, sc, sc.copy(), u)
    assert d["difference"] == 0 and d["ci"] == [0.0, 0.0]
    # and the same two results get the same interval, whoever else is scored
    a = evaluate_runs(y, runs, CLASSES, resamples=idx, uniforms=u)
    b = evaluate_runs(y, runs.copy(), CLASSES, resamples=idx, uniforms=u)
    assert a["ci"] == b["ci"]


def test_a_paired_difference_is_narrower_than_an_unpaired_one():
    rng = np.random.default_rng(3)
    y = np.array(["HELI"] * 40 + ["QUAD"] * 40)
    a = _preds(y, (0.8, 0.8), rng)
    b = a.copy()
    b[np.flatnonzero(a == y)[:4]] = np.where(y[np.flatnonzero(a == y)[:4]] == "HELI", "QUAD", "HELI")  # 4 more errors
    idx, u = resample_indices(y.size, 1000, 0), seed_uniforms(1000, 1, 0)
    sa, sb = run_scores(y, a[None], CLASSES, idx), run_scores(y, b[None], CLASSES, idx)
    pa, pb = (run_scores(y, x[None], CLASSES, np.arange(y.size)[None])[:, 0] for x in (a, b))
    d = paired_difference(pa, pb, sa, sb, u)
    assert d["difference"] == pytest.approx(0.05) and d["ci"][0] > 0  # b is worse, every resample says so
    other = run_scores(y, b[None], CLASSES, resample_indices(y.size, 1000, 1))  # unpaired resamples
    unpaired = np.percentile(sa[0] - other[0], [2.5, 97.5])
    assert unpaired[0] < 0 < unpaired[1]


# ---- acceptance: one strategy trained with 3 seeds ------------------------------------------------------
def test_three_training_runs_each_lie_inside_the_reported_interval(tmp_path):
    from mdaug.radar.seeds import child_seed
    from mdaug.reports.config import StudyConfig
    from mdaug.reports.executor import SerialExecutor
    from mdaug.reports.study import Study
    from mdaug.strategies import TrainingSpec, training_set

    import dataclasses

    cfg = StudyConfig(seed=7).quick_version()
    cfg.protocol = dataclasses.replace(cfg.protocol, cnn_n_per_class=100, cnn_epochs=4)
    study = Study(cfg, tmp_path, log=lambda *_: None)
    spec = TrainingSpec("sigma_p_published", sigma_p=0.2, normalisation="peak", through_chain=False)
    X, y, _ = training_set(dataclasses.replace(spec, sigma_p=0.4), CLASSES, 40, seed=99)  # other drones, to test on
    run_jobs = study.cnn_jobs({"sigma_p_published": [spec]}, {"sigma_p_published": {"value": 0.2}},
                              ("select", (X[:20], y[:20]), "x"), {"new": (X, y)})
    job = run_jobs["sigma_p_published"]
    first = child_seed(7, "cnn", "sigma_p_published")  # the one-run study's seed: its run is run 0
    assert job["seed"] == first and job["run_seeds"] == [first] + [child_seed(7, "cnn", "sigma_p_published", i)
                                                                   for i in (1, 2)]
    stage = study.training(run_jobs, None, SerialExecutor())[0]["sigma_p_published"]
    assert len(stage["predictions"]["new"]) == 3 and len(set(stage["predictions"]["new"])) > 1
    m = statistics.score(statistics.truth(y, CLASSES), stage["predictions"]["new"], "new", 7, 500,
                         seeds=stage["seeds"])
    lo, hi = m["ci"]["balanced_accuracy"]
    own = [evaluate(y, statistics.decode(p, CLASSES), labels=CLASSES, n_boot=0)["balanced_accuracy"]
           for p in stage["predictions"]["new"]]
    assert m["balanced_accuracy"] == pytest.approx(np.mean(own))
    assert all(lo <= s <= hi for s in own), (own, lo, hi)


# ---- verdicts, and the finding agreeing with the table ------------------------------------------------
def rows_and_finding(results):
    """(finding text, {row name: verdict cell}) as the README writes them."""
    section = results_section(results)
    text = " ".join(finding(results, Text()))
    rows = {name: cells[-1] for name, cells in table_rows(section).items()}
    return text, rows


def check_agreement(results):
    """Every sentence of the finding agrees with the table's verdicts."""
    text, rows = rows_and_finding(results)
    strategies = {n: v for n, v in rows.items() if not n.startswith("ceiling")}
    chance = {n for n, v in strategies.items() if "chance" in v}
    worse = {n for n, v in strategies.items() if "worse than chance" in v}
    if "every balanced-accuracy interval contains 0.5" in text:
        assert chance == set(strategies)
        if worse:
            assert "or lies below it" in text
            for n in worse:
                assert n in text.split("or lies below it")[1].split(")")[0]
    else:
        assert chance != set(strategies)
    labels = text.split("Biased")[-1] if "Biased" in text else text.split("No strategy is biased")[-1]

    def listed(after):
        m = re.search(after + r"[^:]*: ([^;.]*)", labels)
        return set(re.findall(r"[a-z_]+", m.group(1))) - {"and", "degenerate"} if m else set()

    assert listed("not better than chance") == chance - worse
    assert listed("worse than chance") == worse
    for cls in CLASSES:
        m = re.search(r"([a-z_ ,()]+) towards " + cls, labels)
        named = set(re.findall(r"[a-z_]+", m.group(1))) - {"and", "degenerate"} if m else set()
        other = [c for c in CLASSES if c != cls][0]
        expected = {n for n, v in strategies.items()
                    if f"biased towards {cls}" in v or f"degenerate: recognises no {other}" in v}
        assert named == expected, (cls, named, expected)
    for m in re.finditer(r"is (better|worse|level): ([+-]\d\.\d+) \[([+-]\d\.\d+), ([+-]\d\.\d+)\]", text):
        word, lo, hi = m.group(1), float(m.group(3)), float(m.group(4))
        assert word == ("better" if lo > 0 else "worse" if hi < 0 else "level"), m.group(0)


def sibling(name: str):
    """A module of this folder (the tests are imported by path, not as a package)."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


_CACHE = {}


def _synthetic(tmp_path):
    """The report tests' synthetic results (made once; a fresh copy for each test)."""
    if "results" not in _CACHE:
        _CACHE["results"] = sibling("test_report").synthetic_results(tmp_path)
    return copy.deepcopy(_CACHE["results"])


def test_finding_agrees_with_the_table_on_synthetic_results(tmp_path):
    results = _synthetic(tmp_path)
    check_agreement(results)
    text, rows = rows_and_finding(results)
    assert "not better than chance" in rows["posterior"] and "posterior" in text.split("not better than chance")[-1]


def _rescore(results, recalls_by_strategy):
    """Replace the strategies' predictions on 'new' (3 runs) and rescore everything."""
    y = statistics.decode(results["truth"]["new"]["y"], CLASSES)
    for i, (name, rec) in enumerate(recalls_by_strategy.items()):
        results["strategies"][name]["predictions"]["new"] = [
            statistics.encode(_preds(y, rec, np.random.default_rng(10 * i + k)), CLASSES) for k in range(3)]
    statistics.score_study(results)
    results["best_strategy"] = verdicts.best_strategy(results["strategies"], "select")
    return results


def test_all_at_chance_with_two_worse_than_chance_is_said_so(tmp_path):
    """The reported contradiction: 'every interval contains 0.5' while the table labels
    two strategies worse than chance."""
    results = _rescore(_synthetic(tmp_path), {"sigma_p_published": (0.2, 0.5), "sigma_p_fit": (0.3, 0.45),
                                             "posterior": (0.5, 0.5), "posterior_specimens": (0.45, 0.55),
                                             "tsaug": (0.0, 1.0)})
    text, rows = rows_and_finding(results)
    worse = {n for n, v in rows.items() if "worse than chance" in v}
    assert {"sigma_p_published", "sigma_p_fit"} <= worse
    assert "worse than chance" in text
    check_agreement(results)


def test_three_strategies_tied_on_the_selection_set_are_reported_as_tied(tmp_path):
    results = _synthetic(tmp_path)
    for name in ("sigma_p_fit", "posterior", "posterior_specimens"):  # identical selection-set predictions
        results["strategies"][name]["predictions"]["select"] = list(
            results["strategies"]["posterior_specimens"]["predictions"]["select"])
    statistics.score_study(results)
    results["best_strategy"] = verdicts.best_strategy(results["strategies"], "select")
    best = results["best_strategy"]
    assert best["name"] is None and set(best["tied"]) == {"sigma_p_fit", "posterior", "posterior_specimens"}
    assert "within 0.01 of the best" in best["rule"]
    section = results_section(results)
    assert section.count("(tied choice)") == 3 and "(chosen)" not in section
    text = " ".join(finding(results, Text()))
    assert "does not separate" in text and "a tie is reported, not broken" in text
    for name in best["tied"]:
        assert f"**{name}**" in text
    # each comparator is named once, every tied strategy compared with it
    assert text.count("gainst tsaug (") == 1 and text.count("the ceiling of the simulated scene (") == 1
    for name in best["tied"]:
        assert f"{name} is " in text.split("gainst tsaug (")[1].split("; against")[0]
    check_agreement(results)
    # their selection-set comparisons are exactly level
    d = verdicts.comparison(results, "select", "sigma_p_fit", "posterior")
    assert d["difference"] == 0 and d["word"] == "level"


def test_the_ceiling_is_chosen_on_the_selection_set_and_flagged_at_chance(tmp_path):
    results = _synthetic(tmp_path)
    models = results["ceiling"]["models"]
    y_sel = statistics.decode(results["truth"]["select"]["y"], CLASSES)
    y_new = statistics.decode(results["truth"]["new"]["y"], CLASSES)
    rng = np.random.default_rng(0)
    models["nb"]["predictions"]["select"] = [statistics.encode(y_sel, CLASSES)]  # best on select
    models["nb"]["predictions"]["new"] = [statistics.encode(_preds(y_new, (0.5, 0.5), rng), CLASSES)]  # chance
    models["svm"]["predictions"]["new"] = [statistics.encode(y_new, CLASSES)]  # perfect on the test set: not used
    statistics.score_study(results)
    chosen = verdicts.ceiling_choice(models, "select")
    assert chosen["model"] == "nb" and chosen["set"] == "select"
    results["ceiling"]["chosen"] = chosen
    j = verdicts.judge(results)
    assert j["ceiling"]["model"] == "nb" and j["ceiling"]["at_chance"]
    text = " ".join(finding(results, Text(), j))
    assert "the ceiling itself is not better than chance" in text and "svm" not in text
    check_agreement(results)


def test_ceiling_ties_go_to_the_cnn():
    m = {n: {"tests": {"select": {"balanced_accuracy": v}}} for n, v in
         (("svm", 1.0), ("xgb", 0.995), ("nb", 0.7), ("cnn", 0.992))}
    c = verdicts.ceiling_choice(m, "select")
    assert c["model"] == "cnn" and set(c["tied"]) == {"svm", "xgb", "cnn"}


def test_measured_nuisances_far_outside_the_stated_ranges_are_flagged():
    cal = {"HELI": {"acquisition": {"carrier": [0.0, 0.3], "noise_db": [-48.0, -42.0]},
                    "measured_acquisition": {"carrier": [0.05, 0.4], "noise_db": [-79.0, -54.0]}},
           "QUAD": {"acquisition": {"carrier": [0.0, 0.3], "noise_db": [-48.0, -42.0]},
                    "measured_acquisition": {"carrier": [0.38, 0.99], "noise_db": [-49.0, -43.0]}}}
    flags = {(f["class"], f["key"]) for f in verdicts.nuisances(cal)}
    assert flags == {("HELI", "noise_db"), ("QUAD", "carrier")}  # 0.4 and -49 dB are near enough


def test_the_report_flags_far_nuisances_and_prints_the_command_as_run(tmp_path):
    from mdaug.reports.report import write_report

    results = _synthetic(tmp_path)
    results["calibration"]["QUAD"]["measured_acquisition"]["carrier"] = [0.38, 0.99]
    page = write_report(results, tmp_path / "report.html").read_text()
    assert "mdaug run --out /data/my-study" in page and "--out mdaug-study" not in page
    assert "QUAD: the measured carrier return (0.38 to 0.99 x sum(Gamma)) lies far outside" in page
    assert page.count("far outside the stated range") == 1  # and in the calibration section


# ---- the README check: a rerun within the quoted intervals ---------------------------------------------
def test_readme_check_accepts_a_rerun_within_the_intervals_and_names_one_outside(tmp_path):
    results = _synthetic(tmp_path)
    readme = f"# x\n\n{BEGIN}\nold\n{END}\n"
    readme = replace_section(readme, results_section(results))
    rerun = copy.deepcopy(results)
    m = rerun["strategies"]["sigma_p_fit"]["tests"]["new"]
    lo, hi = m["ci"]["balanced_accuracy"]
    m["balanced_accuracy"] = hi - 0.3 * (hi - lo)  # moved, inside the quoted interval
    assert results_section(rerun) != results_section(results)
    assert check_readme(readme, rerun) == []
    m["balanced_accuracy"] = hi + 0.02
    problems = check_readme(readme, rerun)
    assert len(problems) == 1 and "sigma_p_fit, balanced accuracy" in problems[0] and "outside" in problems[0]
