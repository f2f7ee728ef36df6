"""The study's report (reports/report.py) and the README's results section
(reports/readme.py), on a small synthetic results dict shaped like results.json:
headline first, no raw JSON or repr, alt text, honest labels, rounding, the README
in step with the command it quotes; screenshots in headless Chromium (slow)."""
import dataclasses
import html
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from mdaug.classify import evaluate
from mdaug.reports import figures, statistics, verdicts
from mdaug.reports.config import StudyConfig
from mdaug.reports.readme import BEGIN, END, README, check_readme, current_section, replace_section, results_section
from mdaug.reports.report import SECTIONS, command, decimals, get, write_report
from mdaug.strategies import STRATEGIES

ROOT = Path(__file__).resolve().parents[1]
CLASSES = ["HELI", "QUAD"]


def _predictions(n_heli, n_quad, recall_heli, recall_quad, rng):
    y = np.array(["HELI"] * n_heli + ["QUAD"] * n_quad)
    p = y.copy()
    for cls, other, r, n in (("HELI", "QUAD", recall_heli, n_heli), ("QUAD", "HELI", recall_quad, n_quad)):
        idx = np.flatnonzero(y == cls)
        wrong = rng.choice(idx, size=int(round((1 - r) * n)), replace=False)
        p[wrong] = other
    return y, p


SIZES = {"select": (12, 12), "new": (44, 92), "new_large": (176, 368)}


def _runs(recall_heli, recall_quad, set_name, seed, n_runs=3, step=0.03):
    """Encoded predictions of n_runs training runs on a set (recalls moved by +-step
    from run to run, except 0 and 1, which every run keeps: a degenerate class stays so)."""
    out = []
    for i in range(n_runs):
        d = step * (i - (n_runs - 1) / 2)
        rh = recall_heli if recall_heli in (0.0, 1.0) else min(max(recall_heli + d, 0), 1)
        rq = recall_quad if recall_quad in (0.0, 1.0) else min(max(recall_quad - d, 0), 1)
        _, p = _predictions(*SIZES[set_name], rh, rq, np.random.default_rng(1000 * seed + i))
        out.append(statistics.encode(p, CLASSES))
    return out


def _metrics(recall_heli, recall_quad, n_heli=44, n_quad=92, seed=0):
    y, p = _predictions(n_heli, n_quad, recall_heli, recall_quad, np.random.default_rng(seed))
    return evaluate(y, p, labels=CLASSES, n_boot=300, random_state=seed)


def _png(path):
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 1))
    ax.plot([0, 1])
    fig.savefig(path)
    plt.close(fig)
    return str(path)


def synthetic_results(folder: Path, sbc: bool = False) -> dict:
    """A results dict with the layout of results.json (default config, seed 0):
    sigma_p_published and tsaug degenerate (all QUAD), posterior at chance, sigma_p_fit
    and posterior_specimens useful; NaN and inf where results.json has them."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "figures").mkdir(exist_ok=True)
    cfg = StudyConfig()
    recalls = {"sigma_p_published": (0.0, 1.0), "sigma_p_fit": (0.75, 0.85), "posterior": (0.5, 0.52),
               "posterior_specimens": (0.8, 0.82), "tsaug": (0.0, 1.0)}
    settings = {"sigma_p_published": ("sigma_p", 0.3), "sigma_p_fit": ("sigma_p", 0.1),
                "posterior_specimens": ("width", 1.0)}
    select = {"sigma_p_published": (0.4, 0.9), "sigma_p_fit": (0.8, 0.85), "posterior": (0.6, 0.6),
              "posterior_specimens": (0.9, 0.9), "tsaug": (0.2, 1.0)}
    strategies = {}
    for i, (name, (rh, rq)) in enumerate(recalls.items()):
        param = settings.get(name)
        strategies[name] = {
            "strategy": name, "model": "cnn", "n_train": 12000, "spec": {"strategy": name},
            "sigma_p": param[1] if param and param[0] == "sigma_p" else None,
            "width": param[1] if param and param[0] == "width" else None, "seeds": [11, 12, 13],
            "data_seconds": 3.0 + i, "train_seconds": 40.0 + 7 * i,
            "predictions": {"select": _runs(*select[name], "select", i),
                            "new": _runs(rh, rq, "new", 10 + i), "new_large": _runs(rh, rq, "new_large", 20 + i)}}
    rows = []
    for name, (param, _) in settings.items():
        values = cfg.protocol.sigma_p if param == "sigma_p" else cfg.protocol.specimen_widths
        for v in values:
            for model in cfg.protocol.models:
                for s, (n1, n2) in (("select", (12, 12)), ("new", (44, 92)), ("new_large", (176, 368))):
                    m = _metrics(0.6 + 0.2 * v, 0.7, n1, n2, seed=int(100 * v) + len(rows))
                    rows.append({"strategy": name, "parameter": param, "value": float(v), "model": model,
                                 "test_set": s, "accuracy": m["accuracy"], "balanced_accuracy": m["balanced_accuracy"],
                                 "balanced_lo": m["ci"]["balanced_accuracy"][0],
                                 "balanced_hi": m["ci"]["balanced_accuracy"][1],
                                 "min_recall": min(c["recall"] for c in m["per_class"].values()),
                                 "train_seconds": 0.5})
    choice = {name: {"value": value, "parameter": param, "set": "select",
                     "scores": {str(float(v)): 0.6 for v in (cfg.protocol.sigma_p if param == "sigma_p"
                                                           else cfg.protocol.specimen_widths)},
                     "rule": f"best mean balanced accuracy of svm, nb, xgb; ties within 0.01 to the smaller {param}"}
              for name, (param, value) in settings.items()}

    def calibration(cls, engines):
        rng = np.random.default_rng(len(cls))
        f = np.sort(rng.uniform(1000, 15000, (engines, 4)), axis=-1)
        a = rng.uniform(0.0005, 0.004, (engines, 4))
        diag = {"sampler": "emcee", "converged": cls == "HELI",
                "reason": "converged: chain 61 x max tau" if cls == "HELI" else
                "NOT CONVERGED: time budget of 240 s ended at 17.2 x max tau (88 steps; need 50)",
                "tau": {"A_a[0]": 30.1}, "ess": {"A_a[0]": 900.5}, "tau_max": 88.2, "ess_min": 612.3,
                "chain_steps": 1500, "steps_over_tau": 17.2, "acceptance_mean": 0.31, "n_walkers": 36,
                "burn": 300, "thin": 20, "seconds": 240.2, "min_tau_multiple": 50.0,
                "identified": {"A_a[0]": False, "w_a[0]": True}, "sd_ratio": {"A_a[0]": 0.7},
                "identified_ratio": 0.5}
        out = {"posterior": str(folder / "posteriors" / f"{cls}.nc"),
               "corner": _png(folder / "figures" / f"corner_{cls}.png"),
               "trace": _png(folder / "figures" / f"trace_{cls}.png"),
               "converged": cls == "HELI", "diagnostics": diag, "n_profiles": 5,
               "summary": {"Gamma[0]": {"mean": 0.011, "sd": 0.0, "prior_sd": float("nan"), "sd_ratio": float("nan")},
                           "phi_a[0]@0": {"mean": 0.1, "prior_sd": float("inf")}},
               "acquisition": {"ramps": 32, "carrier": [0.0, 0.3], "noise_db": [-48.0, -42.0]},
               "measured_acquisition": {"ramps": 32, "carrier": [0.1, 0.25], "noise_db": [-47.0, -43.5]},
               "lines": {"frequency_q": np.stack([f * 0.95, f, f * 1.05]).tolist(),
                         "amplitude_q": np.stack([a * 0.7, a, a * 1.3]).tolist(),
                         "reference_frequency": (f * 1.1).tolist()}}
        if sbc:  # the smc route of an estimator file, with its stored SBC
            diag.update(route="smc", estimator={"sbc": {"smc": {
                "outer_share": 0.32, "coverage90_range": [0.6, 0.8], "pooled_p": 0.01, "n_replicates": 16}}},
                smc={"converged": cls == "HELI", "likelihood": "summary", "particles": 1000, "stages": 6,
                     "unique_share": 0.62, "acceptance_last": 0.31, "seconds": 5.8})
        return out

    ceiling = {"n_train": 2000, "what": "trained on the scene simulator's own data (1000 acquisitions per class)",
               "models": {m: {"train_seconds": t, "seeds": list(range(k)),
                              "predictions": {"select": _runs(0.95, 0.95, "select", 40 + j, k),
                                              "new": _runs(0.85, 0.8, "new", 50 + j, k),
                                              "new_large": _runs(0.85, 0.8, "new_large", 60 + j, k)}}
                          for j, (m, t, k) in enumerate((("svm", 2.0, 1), ("xgb", 5.0, 1), ("nb", 0.01, 1),
                                                         ("cnn", 30.0, 3)))}}
    speed = {"rows": [
        {"stage": "generator", "setting": "f(x) QUAD float64", "seconds": 0.3, "rate": "6,600 profiles/s",
         "error": 0.0, "error_metric": "max |profile - float64| (peak = 1)"},
        {"stage": "generator", "setting": "f(x) QUAD float32", "seconds": 0.06, "rate": "33,000 profiles/s",
         "error": 2.97e-07, "error_metric": "max |profile - float64| (peak = 1)"},
        *({"stage": "likelihood", "setting": f"marginal, O = {o} acquisitions x 8 ramps (HELI, 5 meas.)",
           "seconds": 1e-4 * o, "rate": f"{0.1 * o:.2f} ms / evaluation", "error": 0.02 / np.sqrt(o),
           "error_metric": "rms Monte Carlo error of the model mean (peak = 1)"} for o in (4, 8, 16, 32)),
        {"stage": "chain path", "setting": "literal chain, HELI, K = 32", "seconds": 0.4, "rate": "25.00 ms / profile",
         "error": 0.0, "error_metric": "max |reduced - literal| on the same draws (peak = 1, ADC off)"},
        {"stage": "chain path", "setting": "reduced chain, HELI, K = 32", "seconds": 0.05, "rate": "3.10 ms / profile",
         "error": 1.3e-07, "error_metric": "max |reduced - literal| on the same draws (peak = 1, ADC off)"}]}
    data = {"calibration_HELI": {"path": "x", "n": 5, "per_class": {"HELI": 5, "QUAD": 0}},
            "calibration_QUAD": {"path": "x", "n": 5, "per_class": {"HELI": 0, "QUAD": 5}},
            "select": {"path": "x", "n": 24, "per_class": {"HELI": 12, "QUAD": 12}},
            "new": {"path": "x", "n": 136, "per_class": {"HELI": 44, "QUAD": 92}},
            "new_large": {"path": "x", "n": 544, "per_class": {"HELI": 176, "QUAD": 368}}}
    truth = {t: statistics.truth(_predictions(*n, 1, 1, np.random.default_rng(0))[0], CLASSES)
             for t, n in SIZES.items()}
    results = {
        "config": json.loads(json.dumps(cfg.to_dict())), "simulated": True, "data": data,
        "acquisition": {"ramps": 32, "phases": "uniform", "carrier": [0.0, 0.3], "noise_db": [-48.0, -42.0]},
        "acquisition_text": "K = 32 ramp(s) per frame, uniform phases",
        "selection": {"set": "select", "what": "held-out acquisitions of the calibration drones"},
        "calibration": {"HELI": calibration("HELI", 1), "QUAD": calibration("QUAD", 4)},
        "candidates": {"rows": rows, "selection_set": "select"}, "choice": choice,
        "published_peeking_choice": {"value": 0.0, "parameter": "sigma_p", "set": "new", "scores": {"0.0": 0.5}},
        "truth": truth, "strategies": strategies, "strategy_text": {n: STRATEGIES[n].text for n in strategies},
        "invocation": "mdaug run --out /data/my-study", "ceiling": ceiling, "speed": speed, "profiles_figure": _png(folder / "figures" / "profiles.png"),
        "timings": {"data": 40.0, "calibrate_HELI": 250.0}, "resumed_stages": ["data"], "total_seconds": 900.0}
    results = statistics.score_study(json.loads(json.dumps(results)))
    results["best_strategy"] = verdicts.best_strategy(results["strategies"], "select")
    results["ceiling"]["chosen"] = verdicts.ceiling_choice(results["ceiling"]["models"], "select")
    return json.loads(json.dumps(results))  # as read back from results.json (NaN, Infinity included)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    folder = tmp_path_factory.mktemp("report")
    results = synthetic_results(folder)
    page = write_report(results, folder / "report.html").read_text()
    return results, page, folder


def visible_text(page: str) -> str:
    """The page's text as a reader sees it (no style, no tags, entities decoded)."""
    body = re.sub(r"<style>.*?</style>", "", page, flags=re.S)
    body = re.sub(r"</?(span|b|i|a|code)\b[^>]*>", "", body)  # inline: no space
    body = re.sub(r"<[^>]+>", " ", body)
    return html.unescape(body)


def test_headline_comes_first_and_says_the_finding(report):
    results, page, _ = report
    head = page.index("class='headline'")
    assert head < page.index("<table") and head < page.index("<img")
    text = visible_text(page[head:page.index("</p>", head)])
    best = results["best_strategy"]["name"]
    assert best in text and "tsaug" in text and "ceiling" in text
    assert re.search(r"\d\.\d\d \[\d\.\d\d, \d\.\d\d\]", text)  # numbers with intervals
    assert "sigma_p_published (degenerate)" in text and "towards QUAD" in text
    assert "posterior" in text.split("not better than chance")[-1]  # named as no better than chance


def test_no_raw_json_or_python_repr_on_the_page(report):
    _, page, _ = report
    text = visible_text(page)
    for bad in ('{"', "{'", "NaN", "Infinity", " nan", " inf ", "None", "True", "False", "np.", "array(",
                "':", "[["):
        assert bad not in text, bad
    assert not re.search(r"\d\.\d{5,}", text)  # no 16-digit floats


def test_every_image_has_alt_text_and_is_embedded(report):
    _, page, _ = report
    imgs = re.findall(r"<img[^>]*>", page)
    assert len(imgs) >= 8
    for tag in imgs:
        alt = re.search(r'alt="([^"]*)"', tag)
        assert alt and alt.group(1).strip(), tag[:80]
        assert 'src="data:image/png;base64,' in tag


def test_sections_and_folded_details(report):
    _, page, _ = report
    for sid in SECTIONS:
        assert f'<section id="{sid}">' in page
    assert page.count("<details>") >= 8
    order = [page.index(f'<section id="{sid}">') for sid in SECTIONS]
    assert order == sorted(order)


def test_degenerate_and_chance_are_labelled_and_undefined_precision_is_a_dash(report):
    results, page, _ = report
    start = page.index('<section id="strategies">')
    table = page[start:page.index("<details>", start)]
    rows = {re.search(r"<td>(\w+)", r).group(1): r for r in re.findall(r"<tr.*?</tr>", table, flags=re.S)[1:]}
    precision = _precision_rows(page)
    for name in ("sigma_p_published", "tsaug"):
        assert "degenerate: recognises no HELI (never predicts HELI)" in rows[name]
        assert "no better than always answering QUAD (0.68)" in rows[name]
        cells = re.findall(r"<td[^>]*>(.*?)</td>", precision[name], flags=re.S)
        assert cells[2] == "–"  # precision HELI: HELI is never predicted
    assert "not better than chance" in rows["posterior"]
    assert "degenerate" not in rows["sigma_p_fit"] and "chance" not in rows["sigma_p_fit"]
    assert "always answering QUAD scores accuracy 0.68" in visible_text(page)


def _precision_rows(page: str) -> dict:
    """{strategy: row} of the accuracy-and-precision table below the strategies' table."""
    start = page.index('<section id="strategies">')
    start = page.index("<details>", start)
    table = page[start:page.index("</details>", start)]
    return {re.search(r"<td>(\w+)", r).group(1): r for r in re.findall(r"<tr.*?</tr>", table, flags=re.S)[1:]}


def test_numbers_match_results_and_are_rounded_to_their_interval(report):
    results, page, _ = report
    cells = re.findall(r'data-key="([^"]+)">([^<\s]+)</span>(?:<br>| )<span class="ci">\[<span data-key="([^"]+)\.0">',
                       page)
    assert len(cells) > 40
    for key, shown, ci_key in cells:
        ci = get(results, ci_key)
        d = len(shown.split(".")[1]) if "." in shown else 0
        # at least its interval's precision (the column's: one rule per column, tests/test_report_tables.py)
        assert d >= decimals(ci) or ci[1] <= ci[0], (key, shown, ci)
        assert float(shown) == pytest.approx(get(results, key), abs=0.51 * 10.0 ** -d)
    for key, shown in re.findall(r'data-key="([^"]+)">([^<\s]+)', page):
        assert float(shown) == pytest.approx(float(get(results, key)),
                                             abs=0.51 * 10.0 ** -(len(shown.split(".")[1]) if "." in shown else 0)), key


def test_decimals_follow_the_interval():
    assert decimals([0.60, 0.76]) == 2  # half-width 0.08
    assert decimals([0.5, 0.74]) == 2   # 0.12: two significant digits (PDG)
    assert decimals([0.2, 1.0]) == 1    # 0.4
    assert decimals([0.50, 0.56]) == 3  # 0.03
    assert decimals([0.5, 0.5]) == 2 and decimals(None) == 2


def test_calibration_shows_status_and_sbc(tmp_path):
    results = synthetic_results(tmp_path)
    page = write_report(results, tmp_path / "report.html").read_text()
    text = visible_text(page)
    assert "HELI: likelihood route: converged; SBC: no SBC stored" in text
    assert "QUAD: likelihood route: NOT converged; SBC: no SBC stored" in text
    assert text.count("no SBC stored for the likelihood route (see docs/calibration.md)") == 2
    assert "figures/corner_QUAD.png" in page  # the full corner plot, linked
    with_sbc = synthetic_results(tmp_path / "sbc", sbc=True)
    text = visible_text(write_report(with_sbc, tmp_path / "sbc" / "report.html").read_text())
    assert "HELI: smc route: converged; SBC: overconfident" in text
    assert ("tempered SMC from the amortized posterior on the estimator's summary likelihood: 1000 particles, 6 "
            "stages, distinct share 0.62;") in text
    assert ("overconfident: on 16 simulated drones, outer-10% share 0.320 (at most 0.13; 0.10 expected), 90% "
            "coverage 0.60-0.80 per quantity (at least 0.85); the rank histograms are not flat either (p = 0.01)"
            in text)


def test_choice_section_states_the_rule_and_the_unused_peeking_choice(report):
    _, page, _ = report
    text = visible_text(page[page.index('<section id="choice">'):page.index('<section id="profiles">')])
    assert "balanced accuracy" in text and "never on a test set" in text
    assert "not used" in text and "sigma_P = 0.00" in text
    assert "chosen blind to what it models" in text  # a specimen width was chosen


def test_choice_section_warns_about_the_width_only_when_one_was_chosen(tmp_path):
    results = synthetic_results(tmp_path)
    results["choice"].pop("posterior_specimens")
    text = visible_text(write_report(results, tmp_path / "report.html").read_text())
    assert "never on a test set" in text and "chosen blind" not in text


def test_figures_have_units_and_readable_fonts(report):
    import matplotlib.pyplot as plt

    results, _, _ = report
    figs = [figures.strategies_figure(results, "new", "sigma_p_fit", ("svm", 0.8, [0.7, 0.9])),
            figures.sweeps_figure(results, "new"),
            figures.posterior_lines_figure(results["calibration"]["QUAD"], "QUAD"),
            figures.speed_figure(results, "new"), figures.confusion_figure(results, "new")]
    for fig in figs:
        assert fig.get_figwidth() <= 10.5  # shown at 1:1 in the report's column
        for ax in fig.axes:
            if not ax.axison:
                continue
            ylabel = any(a.get_ylabel().strip() for a in ax.get_shared_y_axes().get_siblings(ax))
            assert ax.get_xlabel().strip() and ylabel, ax.get_title()
            for t in ax.texts + [ax.xaxis.label, ax.yaxis.label, ax.title] + ax.get_xticklabels():
                if t.get_text():
                    assert t.get_fontsize() >= 9, t.get_text()
        plt.close(fig)


def test_profiles_figure_is_in_metres(tmp_path):
    """x is range from the target in metres: the label says m (and the bin in mm), every
    curve spans the 400-bin slice's length in metres of the radar's chain range, centred
    on the target, and the view is the +-80 bins around it."""
    from mdaug.radar import RadarConfig

    radar = RadarConfig()
    n_bins, bin_m = radar.slice_length, radar.bin_m
    rng = np.random.default_rng(0)
    prof = {c: rng.random((5, n_bins)) for c in CLASSES}
    fig = figures.profiles_figure(prof, {"posterior": prof})
    axes = fig.axes
    assert len(axes) == len(CLASSES)
    label = axes[-1].get_xlabel()
    assert label.startswith("range from the target (m;") and f"1 bin = {1e3 * bin_m:.2f} mm" in label
    for ax in axes:
        lines = ax.get_lines()
        assert len(lines) == 2  # measured and posterior medians
        for line in lines:
            x = np.asarray(line.get_xdata())
            assert len(x) == n_bins
            assert x[-1] - x[0] + bin_m == pytest.approx(n_bins * bin_m)  # the slice's length in metres
            assert x[n_bins // 2] == 0.0 and np.allclose(np.diff(x), bin_m)
        assert ax.get_xlim() == pytest.approx((-80 * bin_m, 80 * bin_m))
    other = figures.profiles_figure(prof, {}, bin_m=0.01)
    wide = other.axes[0].get_lines()[0].get_xdata()
    assert wide[-1] - wide[0] == pytest.approx((n_bins - 1) * 0.01)  # bins become metres at the given width
    figures.pyplot().close(fig)
    figures.pyplot().close(other)
    path = figures.measured_vs_synthetic(prof, {"posterior": prof}, tmp_path / "p.png")
    assert path.is_file() and path.stat().st_size > 0


# ---- the README ----------------------------------------------------------------------------------
def test_readme_section_quotes_the_command_and_its_table(tmp_path):
    results = synthetic_results(tmp_path)
    section = results_section(results)
    assert section.startswith(BEGIN) and section.endswith(END)
    assert "```bash\nmdaug run --out mdaug-study\n```" in section and "Seed 0 (the default)" in section
    assert "| sigma_p_published |" in section and "degenerate" in section
    best = results["best_strategy"]["name"]
    assert f"| {best} (chosen) |" in section
    bal = results["strategies"][best]["tests"]["new"]
    d = decimals(bal["ci"]["balanced_accuracy"])
    assert f"{bal['balanced_accuracy']:.{d}f} [" in section
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n{BEGIN}\nold\n{END}\n\nrest\n")
    readme.write_text(replace_section(readme.read_text(), section))
    assert check_readme(readme.read_text(), results) == []
    assert readme.read_text().endswith("\n\nrest\n")
    results["strategies"][best]["tests"]["new"]["balanced_accuracy"] -= 0.1
    assert check_readme(readme.read_text(), results)  # a changed number is caught


def test_readme_section_refuses_results_of_another_command(tmp_path):
    results = synthetic_results(tmp_path)
    results["config"]["seed"] = 4
    assert "mdaug run --out mdaug-study --seed 4" in results_section(results)
    results["config"]["protocol"]["cnn_epochs"] = 3
    with pytest.raises(ValueError, match="protocol.cnn_epochs"):
        results_section(results)
    quick = json.loads(json.dumps(dataclasses.asdict(StudyConfig().quick_version())))
    assert command({"config": quick}) == "mdaug run --quick --out mdaug-study"


def test_readme_results_section_belongs_to_the_quick_start_command():
    text = README.read_text()
    assert README == ROOT / "README.md"
    section = current_section(text)
    default = command({"config": json.loads(json.dumps(StudyConfig().to_dict()))})
    assert default == "mdaug run --out mdaug-study"
    assert f"pip install -e . && {default}" in text  # the Quick start
    if "|" in section:  # filled: it quotes exactly the Quick start's command
        assert f"```bash\n{default}\n```" in section and "Seed 0 (the default)" in section


@pytest.mark.slow
def test_readme_table_check_accepts_a_rerun_of_the_quoted_command(tmp_path, capsys):
    """The full default study (MDAUG_STUDY_DIR=DIR checks a finished run's
    DIR/results.json instead), checked against the README's section by
    `tests/benchmarks/readme_table.py DIR --check`: every figure of the rerun within the
    interval the README quotes for it."""
    import importlib.util
    import os

    from mdaug.cli import main

    folder = os.environ.get("MDAUG_STUDY_DIR")
    if folder is None:
        folder = tmp_path / "mdaug-study"
        assert main(["run", "--quiet", "--out", str(folder)]) in (0, 1)
    spec = importlib.util.spec_from_file_location("readme_table", ROOT / "tests" / "benchmarks" / "readme_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    status = mod.main([str(folder), "--check"])
    assert status == 0, capsys.readouterr().out


# ---- screenshots ----------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.skipif(not any(shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome")),
                    reason="no headless Chromium")
def test_report_screenshots(report, tmp_path):
    import importlib.util

    from PIL import Image

    spec = importlib.util.spec_from_file_location("report_screenshots",
                                                  ROOT / "tests" / "benchmarks" / "report_screenshots.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    _, _, folder = report
    shots = mod.shoot(folder / "report.html", tmp_path / "shots")
    page, expanded = shots["page"], shots["expanded"]
    assert 3000 < page[1][1] < expanded[1][1]  # the folded sections hold more
    im = np.asarray(Image.open(page[0]).convert("L"))
    assert im.std() > 10  # not blank


def test_stage_timings_keep_the_time_of_resumed_stages(tmp_path):
    """A resumed run took ~0 s itself: the title gives the stages' own time and says so."""
    results = synthetic_results(tmp_path)  # data 40 s (resumed) + calibrate_HELI 250 s; this run 900 s
    text = visible_text(write_report(results, tmp_path / "report.html").read_text())
    assert "Stage timings (stages 290 s; this run 900 s, 1 stage(s) resumed from the cache)" in text
    results["resumed_stages"] = []
    text = visible_text(write_report(results, tmp_path / "fresh.html").read_text())
    assert "Stage timings (total 290 s)" in text


def test_precision_undefined_in_some_runs_is_their_mean_and_says_over_how_many(tmp_path):
    """A run that never predicts HELI leaves HELI's precision undefined: the mean is over
    the other runs (not a 0 averaged in), and the cell says '2 of 3 runs'."""
    results = synthetic_results(tmp_path / "study")
    s = results["strategies"]["sigma_p_fit"]
    n = len(s["predictions"]["new"][0])
    s["predictions"]["new"][1] = "1" * n  # run 2 answers QUAD for every acquisition
    results = statistics.score_study(results)
    m = s["tests"]["new"]
    heli = m["per_class"]["HELI"]
    own = [r["precision"]["HELI"] for r in m["runs"]]
    assert own[1] is None and heli["precision_runs"] == 2
    assert heli["precision"] == pytest.approx((own[0] + own[2]) / 2)
    page = write_report(results, tmp_path / "report.html").read_text()
    cells = re.findall(r"<td[^>]*>(.*?)</td>", _precision_rows(page)["sigma_p_fit"], flags=re.S)
    assert 'data-key="strategies.sigma_p_fit.tests.new.per_class.HELI.precision"' in cells[2]
    assert "2 of 3 runs" in cells[2] and "of 3 runs" not in cells[3]


def test_readme_calibration_line_tells_the_amortized_posterior_from_its_check_route(tmp_path):
    """An amortized calibration is reported in the status words (route, exact draws, the
    gate's verdict on its stored SBC), and the smc route run beside it keeps its own
    verdict (NOT converged) and its run's facts."""
    results = synthetic_results(tmp_path)
    cls = next(iter(results["calibration"]))
    results["calibration"][cls]["converged"] = True
    results["calibration"][cls]["diagnostics"] = {
        "sampler": "amortized",
        "estimator": {"sbc": {"amortized": {"outer_share": 0.114, "coverage90_range": [0.83, 0.91],
                                            "n_replicates": 300}}},
        "smc": {"converged": False, "particles": 3600, "stages": 12, "unique_share": 0.41}}
    line = next(x for x in results_section(results).splitlines() if x.startswith("Calibration:"))
    # coverage 0.83 < 0.85: overconfident by the one gate, though the outer share passes
    assert (f"{cls} amortized route: exact draws; SBC: overconfident (on 300 simulated drones, outer-10% share "
            "0.114 (at most 0.13; 0.10 expected), 90% coverage 0.83-0.91 per quantity (at least 0.85)); smc "
            "route, run as a check: NOT converged (3600 particles, 12 stages, distinct share 0.41)") in line
