"""The report's "Run details" section: the data sets, the acquisition, the
configuration and the stage timings, all folded."""
from __future__ import annotations

from .markup import Html, details, table, td
from .numbers import fmt, plain


def _flatten(d: dict) -> list[tuple[str, object]]:
    """Config rows: the sections (data, simulation, protocol) one level deep."""
    out = []
    for k, v in d.items():
        if k in ("data", "simulation", "protocol") and isinstance(v, dict):
            out += [(f"{k}.{kk}", vv) for kk, vv in v.items()]
        else:
            out.append((k, v))
    return out


def timings_title(r: dict) -> str:
    """'Stage timings (...)': the stages' own seconds (a resumed stage keeps the time it took
    when it ran) and, after a resume, this invocation's wall time beside them."""
    stages = sum((r.get("timings") or {}).values())
    resumed = len(r.get("resumed_stages") or [])
    if not resumed:
        return f"Stage timings (total {fmt(stages, 0)} s)"
    return (f"Stage timings (stages {fmt(stages, 0)} s; this run {fmt(r.get('total_seconds'), 0)} s, "
            f"{resumed} stage(s) resumed from the cache)")


def details_section(r: dict, w: Html) -> str:
    rows = [[td(w.esc(n), False), td(str(d["n"])), td(w.esc(plain(d.get("per_class"))), False)]
            for n, d in r["data"].items()]
    data = table(["set", "acquisitions", "per class"], rows)
    acq = table(["setting", "value"], [[td(w.esc(k), False), td(w.esc(plain(v)), False)]
                                      for k, v in r["acquisition"].items()])
    cfg = table(["setting", "value"], [[td(w.esc(k), False), td(w.esc(plain(v)), False)]
                                      for k, v in _flatten(r["config"])])
    tim = table(["stage", "seconds", "resumed from cache"],
                [[td(w.esc(k), False), td(w.num(f"timings.{k}", v, 1)),
                  td("yes" if k in r.get("resumed_stages", []) else "no")]
                 for k, v in (r.get("timings") or {}).items()])
    return (details("Data sets", data) + details(f"Acquisition: {r['acquisition_text']}", acq)
            + details("Configuration", cfg) + details(timings_title(r), tim))
