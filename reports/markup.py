"""The page's building blocks: two writers of one interface (:class:`Html` for the
report, :class:`Text` for the README's markdown) and the HTML pieces (sections, folded
details, tables, embedded images).

Every number taken from ``results.json`` carries ``data-key`` on the page, its path
there (dot-separated), so the report and the results can be checked against each other.
"""
from __future__ import annotations

import base64
import html
from pathlib import Path

from .numbers import decimals, fmt

CSS = """body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;max-width:1080px;margin:auto;
padding:1em 1.2em;line-height:1.45;color:#222}
h1{font-size:1.6em;margin-bottom:.3em}h2{border-bottom:1px solid #ddd;padding-bottom:.15em;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.95em}td,th{border:1px solid #d4d4d4;padding:3px 7px;
vertical-align:top}th{background:#f3f3f3;text-align:left}td.n{text-align:right;white-space:nowrap}
tr.chosen td{background:#eef5fc}td.verdict{min-width:13em}.ci{color:#666;font-size:.85em;white-space:nowrap}
.ci.wrap{white-space:normal}
.warn{color:#b00020;font-weight:600}.flag{color:#b00020}.ok{color:#1b7a3a;font-weight:600}
img{max-width:100%;height:auto;display:block;margin:.4em 0}
.headline{font-size:1.12em;background:#f6f8fa;border-left:4px solid #1f78b4;padding:.6em .9em;margin:.6em 0}
details{margin:.6em 0;border:1px solid #e2e2e2;border-radius:4px;padding:.3em .7em}
summary{cursor:pointer;font-weight:600}.note{color:#555;font-size:.93em}nav{font-size:.95em}
nav a{margin-right:1em}code{background:#f3f3f3;padding:0 .25em}"""


class Html:
    """Formatting for the page (numbers tagged with their results.json key)."""

    @staticmethod
    def esc(s) -> str:
        return html.escape(str(s))

    @staticmethod
    def b(s) -> str:
        return f"<b>{html.escape(str(s))}</b>"

    @staticmethod
    def warn(s) -> str:
        return f"<span class='warn'>{s}</span>"

    @staticmethod
    def num(key: str | None, value, d: int = 2) -> str:
        text = fmt(value, d)
        if key is None or text == "–":
            return text
        return f'<span data-key="{html.escape(key)}">{text}</span>'

    def val_ci(self, key: str | None, value, ci_key, ci, d: int | None = None, br: bool = False) -> str:
        """``value [lo, hi]``; ``ci_key``: the interval's key (its items .0 and .1), or
        the pair of keys of lo and hi."""
        d = decimals(ci) if d is None else d
        s = self.num(key, value, d)
        if ci:
            lo, hi = ci_key if isinstance(ci_key, tuple) else (ci_key and ci_key + ".0", ci_key and ci_key + ".1")
            s += ("<br>" if br else " ") + f'<span class="ci">[{self.num(lo, ci[0], d)}, {self.num(hi, ci[1], d)}]</span>'
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
    def warn(s) -> str:
        return f"**{s}**"

    @staticmethod
    def num(key, value, d: int = 2) -> str:
        return fmt(value, d)

    def val_ci(self, key, value, ci_key, ci, d=None, br=False) -> str:
        d = decimals(ci) if d is None else d
        return fmt(value, d) + (f" [{fmt(ci[0], d)}, {fmt(ci[1], d)}]" if ci else "")


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
