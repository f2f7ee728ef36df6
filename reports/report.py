"""The study's report: one self-contained HTML file (figures embedded as PNG data),
read from the top: the finding in a few generated sentences, one figure of the
strategies, the calibration per class, the choices and their sweeps, measured against
synthetic profiles, speed against error; the rest folded away.

This module only assembles the page. Its parts, one idea a module:

* :mod:`.statistics`: every classifier scored on the same resamples (paired);
* :mod:`.verdicts`: every verdict (degenerate, chance, bias, majority, better / level /
  worse, ties, the ceiling's choice, far-outside nuisances), in one place;
* :mod:`.finding`: the sentences, written from the verdicts;
* :mod:`.numbers` (rounding to the interval, "–" for undefined) and :mod:`.markup`
  (HTML pieces; every number carries ``data-key``, its path in ``results.json``);
* the sections: :mod:`.page_strategies`, :mod:`.page_calibration`,
  :mod:`.page_choice`, :mod:`.page_speed`, :mod:`.page_details`.

No raw JSON or Python repr anywhere; every image has alt text.
"""
from __future__ import annotations

from pathlib import Path

from ..radar import atomic_write
from .finding import command, context, finding
from .markup import CSS, Figures, Html, img, section
from .numbers import decimals, get
from .page_calibration import calibration_section
from .page_choice import choice_section
from .page_details import details_section
from .page_speed import speed_section
from .page_strategies import strategies_section
from .verdicts import judge

SECTIONS = ("finding", "strategies", "calibration", "choice", "profiles", "speed", "details")

__all__ = ["SECTIONS", "write_report", "page", "command", "decimals", "get"]


def page(results: dict, path: Path) -> str:
    """The report's HTML for ``results`` (figures saved beside ``path``)."""
    path = Path(path)
    w = Html()
    j = judge(results)
    figs = Figures(path.parent / "figures")
    sentences = finding(results, w, j)
    toc = "".join(f"<a href='#{sid}'>{t}</a>" for sid, t in (
        ("strategies", "Strategies"), ("calibration", "Calibration"), ("choice", "Choices and sweeps"),
        ("profiles", "Profiles"), ("speed", "Speed"), ("details", "Run details")))
    body = [
        section("finding", "Finding", f"<p class='headline' id='headline'>{' '.join(sentences)}</p>"
                f"<p class='note'>{context(results, w, j)}</p><nav>{toc}</nav>"),
        section("strategies", "Strategies on new drones", strategies_section(results, j, figs, w)),
        section("calibration", "Calibration", calibration_section(results, figs, w, path.parent)),
        section("choice", "Choices (made without the test sets) and the sweeps", choice_section(results, j, figs, w)),
        section("profiles", "Measured against synthetic profiles",
                "<p class='note'>The new drones' measured profiles beside each model-based strategy's profiles at "
                "its chosen setting (tsaug's are distorted copies of the calibration measurements and are not "
                "shown).</p>"
                + img(results.get("profiles_figure"), "Measured and synthetic range profiles per class: median "
                      "and 10-90% band against range from the target in metres")),
        section("speed", "Speed against error", speed_section(results, j, figs, w)),
        section("details", "Run details", details_section(results, w)),
    ]
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>mdaug study report</title>"
            f"<meta name='viewport' content='width=device-width, initial-scale=1'><style>{CSS}</style></head><body>"
            f"<h1>mdaug study: which augmentation classifies new drones</h1>{''.join(body)}</body></html>")


def write_report(results: dict, path) -> Path:
    """Write the report of a finished study to ``path`` (atomic); its figures go to
    ``figures/report_*.png`` beside it (and are embedded)."""
    doc = page(results, Path(path))
    return atomic_write(Path(path), lambda fh: fh.write(doc.encode()))
