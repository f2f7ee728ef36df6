"""The study's report: one self-contained HTML file (figures embedded as PNG data).

Every number in a table carries ``data-key``, the path of that number in
``results.json`` (dot-separated), so the report and the results can be checked
against each other.
"""
from __future__ import annotations

import base64
import html
import json
from importlib import resources
from pathlib import Path

from ..radar import atomic_write


def published_results() -> dict:
    """The published study's figures (packaged copy of reference/published_results.json)."""
    return json.loads(resources.files("mdaug.reports").joinpath("data/published_results.json").read_text())


def get(results: dict, key: str):
    v = results
    for part in key.split("."):
        v = v[part] if isinstance(v, dict) else v[int(part)]
    return v


def fmt(v, digits: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return html.escape(str(v))


def cell(results: dict, key: str, digits: int = 3) -> str:
    return f'<td data-key="{html.escape(key)}">{fmt(get(results, key), digits)}</td>'


def img(path, alt: str) -> str:
    p = Path(path) if path else None
    if p is None or not p.is_file():
        return f"<p class='missing'>figure {html.escape(str(path))} missing</p>"
    data = base64.b64encode(p.read_bytes()).decode()
    return f'<img src="data:image/png;base64,{data}" alt="{html.escape(alt)}"/>'


def section(sid: str, title: str, body: str) -> str:
    return f'<section id="{sid}"><h2>{html.escape(title)}</h2>\n{body}\n</section>'


def _main_test(tests: dict, sel: str) -> str:
    return "new" if "new" in tests else next(t for t in tests if t != sel)


def headline(r: dict) -> str:
    sel = r["selection"]["set"]
    best = r["best_strategy"]["name"]
    if best is None:
        return "<p>No strategy could be ranked on the selection set.</p>"
    s = r["strategies"][best]
    test = _main_test(s["tests"], sel)
    m = s["tests"][test]
    ci = (m.get("ci") or {}).get("balanced_accuracy")
    text = (f"The best strategy chosen on the selection set ({html.escape(r['selection']['what'])}) is "
            f"<b>{html.escape(best)}</b>: balanced accuracy {m['balanced_accuracy']:.3f}"
            + (f" [{ci[0]:.3f}, {ci[1]:.3f}]" if ci else "") + f" on the '{html.escape(test)}' set.")
    ceil = r.get("ceiling")
    if ceil:
        top = max(ceil["models"].items(), key=lambda kv: kv[1]["tests"][test]["balanced_accuracy"])
        text += (f" The simulator's own ceiling ({top[0]}) reaches {top[1]['tests'][test]['balanced_accuracy']:.3f}.")
    what = ("All measurements here are <b>simulated</b> by mdaug's scene simulator." if r["simulated"] else
            "Measured data from the files of the study config.")
    return (f"<p class='headline'>{text}</p><p>{what} Acquisition: {html.escape(r['acquisition_text'])}. "
            f"Seed {r['config']['seed']}.</p>")


def _strategies(r: dict) -> str:
    classes = r["config"]["classes"]
    sel = r["selection"]["set"]
    rows = []
    for name, s in r["strategies"].items():
        for test, m in s["tests"].items():
            base = f"strategies.{name}.tests.{test}"
            degenerate = any((m["per_class"].get(c) or {}).get("recall") == 0.0 for c in classes)
            row = [f"<td>{html.escape(name)}</td><td>{html.escape(test)}{' (selection)' if test == sel else ''}</td>",
                   cell(r, f"{base}.n", 0), cell(r, f"{base}.balanced_accuracy"), cell(r, f"{base}.accuracy")]
            row += [cell(r, f"{base}.per_class.{c}.recall", 2) for c in classes]
            row.append(f"<td>{'degenerate (a class never predicted)' if degenerate else ''}</td>")
            rows.append("<tr>" + "".join(row) + "</tr>")
    head = ("<tr><th>strategy</th><th>set</th><th>n</th><th>balanced accuracy</th><th>accuracy</th>"
            + "".join(f"<th>recall {c}</th>" for c in classes) + "<th></th></tr>")
    assume = "".join(f"<li><b>{html.escape(n)}</b>: {html.escape(t)}</li>" for n, t in r["strategy_text"].items())
    return f"<table>{head}{''.join(rows)}</table><ul>{assume}</ul>"


def _choice(r: dict) -> str:
    rows = []
    for n, c in r["choice"].items():
        rows.append(f"<tr><td>{html.escape(n)}</td><td>{html.escape(str(c.get('parameter')))}</td>"
                    f"{cell(r, f'choice.{n}.value', 2)}<td>{html.escape(c['set'])}</td></tr>")
    peek = r.get("published_peeking_choice")
    extra = ""
    if peek and peek.get("value") is not None:
        extra = (f"<p>The published way (best on the '{html.escape(peek['set'])}' test set: it peeks at the test "
                 f"data) would choose sigma_P = {peek['value']:.2f}; it is not used.</p>")
    return ("<table><tr><th>strategy</th><th>setting</th><th>chosen</th><th>chosen on</th></tr>"
            + "".join(rows) + "</table>" + extra)


def _calibration(r: dict) -> str:
    parts = []
    for cls, c in r["calibration"].items():
        d = c["diagnostics"]
        flag = "converged" if c["converged"] else "<b class='warn'>NOT CONVERGED</b>"
        parts.append(f"<h3>{html.escape(cls)}: {flag}</h3><p>{html.escape(d.get('reason', ''))}</p>"
                     f"<table><tr><th>chain / max tau</th><th>min ESS</th><th>seconds</th></tr><tr>"
                     f"{cell(r, f'calibration.{cls}.diagnostics.steps_over_tau', 1)}"
                     f"{cell(r, f'calibration.{cls}.diagnostics.ess_min', 0)}"
                     f"{cell(r, f'calibration.{cls}.diagnostics.seconds', 0)}</tr></table>"
                     f"{img(c['corner'], f'{cls} posterior corner plot')}")
    return "".join(parts)


def _speed(r: dict) -> str:
    rows = "".join(f"<tr><td>{html.escape(row['stage'])}</td><td>{html.escape(row['setting'])}</td>"
                   f"<td>{html.escape(row['rate'])}</td>{cell(r, f'speed.rows.{i}.error', 5)}"
                   f"<td>{html.escape(row['error_metric'])}</td></tr>"
                   for i, row in enumerate(r["speed"]["rows"]))
    return ("<table><tr><th>stage</th><th>setting</th><th>speed</th><th>error</th><th>error metric</th></tr>"
            + rows + "</table>")


SECTIONS = ("finding", "strategies", "choice", "profiles", "calibration", "speed")

CSS = """body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em;line-height:1.4}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 6px}
.warn{color:#b00}img{max-width:100%}.headline{font-size:115%}"""


def write_report(results: dict, path) -> Path:
    """Write the report of a finished study to ``path`` (atomic)."""
    body = [
        section("finding", "Finding", headline(results)),
        section("strategies", "Strategies", _strategies(results)),
        section("choice", "Choices (made without the test sets)", _choice(results)),
        section("profiles", "Measured against synthetic profiles",
                img(results.get("profiles_figure"), "measured and synthetic profiles per class")),
        section("calibration", "Calibration", _calibration(results)),
        section("speed", "Speed against error", _speed(results)),
    ]
    doc = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>mdaug study</title><style>{CSS}</style>"
           f"</head><body><h1>mdaug study report</h1>{''.join(body)}</body></html>")
    return atomic_write(path, lambda fh: fh.write(doc.encode()))
