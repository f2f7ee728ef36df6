"""Training an estimator is a job: simulate (resumable shards, workers), train the
posterior and the ratio network (progress bar, early stopping, checkpoints, the
device), then the summary likelihood (:mod:`.emulator`, on the same drones and on
drones simulated near the class reference), end with its own SBC of both routes on
fresh drones and the route table that names the file's default route, save. It uses
:mod:`.amortized`, :mod:`.emulator` and :mod:`.diagnostics`, so it lives above them.

Everything lives in one work folder (``sims/``, ``near/``, ``posterior.ckpt``,
``ratio.ckpt``); a rerun with the same arguments resumes where it stopped.
"""
from __future__ import annotations

import copy
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..radar.seeds import child_seed, seed_sequence
from .amortized.estimator import AmortizedEstimator
from .amortized.nets import NetConfig
from .amortized.simulate import SimulationSpec, load_shards, simulate, simulate_shards
from .amortized.target import LabelFree
from .amortized.train import TrainConfig, device_of, fit, posterior_loss, ratio_loss
from .diagnostics.routes import headline
from .diagnostics.routes import run as run_sbc
from .temperature import amortized_draw, fit_temperature

SBC_MEASUREMENTS = 5
NEAR_WIDTH = 4.0
"""Spreads of the drones simulated near the class reference for the summary likelihood,
x the specimen model's defaults (speed 20%, amplitudes 60%: far wider than the drones
of one model, narrower than the prior)."""


def add_summary(est: AmortizedEstimator, vectors, profiles, work, *, n_near: int, near_width: float = NEAR_WIDTH,
                seed: int = 0, workers: int = 1, shard_size: int = 500, config=None, progress=None,
                log=print) -> AmortizedEstimator:
    """Train the summary likelihood on the prior's drones (vectors, profiles) and n_near
    drones simulated near the reference (``work/near``), and attach it to ``est``."""
    from .emulator.train import EmulatorConfig, train_summary_model

    if n_near:
        near = replace(est.spec, near_width=float(near_width))
        paths = simulate_shards(Path(work) / "near", near, n_near, seed=child_seed(seed, "near"), workers=workers,
                                shard_size=shard_size, progress=progress, log=log)
        xn, yn = load_shards(paths)
        vectors, profiles = np.concatenate([vectors, xn]), np.concatenate([profiles, yn])
    model, report = train_summary_model(vectors, profiles, est.label_free, est.class_name, est.spec.acquisition,
                                        est.spec.radar, config or EmulatorConfig(), seed=child_seed(seed, "summary"),
                                        log=lambda m: log(f"  summary likelihood: {m}"))
    report.update(near_simulations=int(n_near), near_width=float(near_width))
    return est.with_summary(model, report)


def train_estimator(spec: SimulationSpec, n_simulations: int, work, out, *, seed: int = 0, workers: int = 1,
                    device: str = "auto", net_cfg: NetConfig = NetConfig(), train_cfg: TrainConfig = TrainConfig(),
                    post_budget: float | None = None, ratio_budget: float | None = None,
                    sim_budget: float | None = None,
                    sbc_truths: int = 300, sbc_route_truths: int = 0, route_settings=None, sbc_specimens: int = 50,
                    temperature_truths: int = 0,
                    shard_size: int = 500,
                    summary: bool = True, near_simulations: int | None = None, near_width: float = NEAR_WIDTH,
                    summary_cfg=None, start: AmortizedEstimator | None = None, command: str | None = None,
                    progress=None, log=print) -> AmortizedEstimator:
    """The whole job (module doc); writes the estimator to ``out`` and returns it.
    post_budget, ratio_budget: training seconds of each network (default: the
    train_cfg's time budget); sim_budget: simulation seconds (training then uses the
    drones simulated by then); summary: train the summary likelihood too, on the prior's
    drones and ``near_simulations`` (default: half as many) drones of the specimen model
    around the reference at ``near_width`` x its spreads; command: the command line that
    ran the job (kept in the file, so anyone can train it again); start: an estimator
    of the same spec and networks whose weights the training starts from (more drones
    refine a file instead of training from scratch; a budget of 0 keeps that network as
    it is); its summary likelihood is kept, not retrained, unless ``summary`` is False;
    temperature_truths: fresh drones on which the amortized posterior's temperature is
    chosen (:func:`.temperature.fit_temperature`) before its own SBC, on other drones."""
    import torch

    t0 = time.perf_counter()
    work = Path(work)
    dev = device_of(device)
    paths = simulate_shards(work / "sims", spec, n_simulations, seed=child_seed(seed, "sims"), workers=workers,
                            shard_size=shard_size, time_budget=sim_budget, progress=progress, log=log)
    t_sim = time.perf_counter() - t0
    vectors, profiles = load_shards(paths)
    ref = spec.reference
    label_free = LabelFree(ref.n_engines, spec.priors(), ref.to_array())
    u = torch.as_tensor(label_free.to_unbounded(label_free.quantities(vectors)), dtype=torch.float32, device=dev)
    x = torch.as_tensor(profiles, device=dev)
    if start is None:
        torch.manual_seed(child_seed(seed, "init"))
        est = AmortizedEstimator.build(spec, net_cfg, u, x)
    else:
        est = started_from(start, spec, net_cfg, dev, keep_summary=summary)
    log(f"{spec.class_name} K={spec.acquisition.ramps}: {len(u)} simulated drones x {spec.n_measurements} "
        f"measurements in {t_sim:.0f} s; training on {dev}")
    logs = {}
    budgets = {"posterior": post_budget, "ratio": ratio_budget}
    for name, net, loss in (("posterior", est.posterior, posterior_loss), ("ratio", est.ratio, ratio_loss)):
        cfg = train_cfg if budgets[name] is None else replace(train_cfg, time_budget=budgets[name])
        tl = fit(net, loss, u, x, cfg, child_seed(seed, name), checkpoint=work / f"{name}.ckpt",
                 progress=progress, desc=f"train {name}", log=log)
        logs[name] = tl.to_dict()
        log(f"  {name}: {tl.epochs} epochs, best validation loss {tl.best_val:.4f} at epoch {tl.best_epoch} "
            f"({tl.stopped}), {tl.seconds:.0f} s")
    del x
    if start is not None:
        logs["start_from"] = {"n_simulations": start.meta.get("n_simulations"), "seed": start.meta.get("seed"),
                              "command": start.meta.get("command"),
                              "summary": "kept" if est.summary is not None else "none"}
    if summary and est.summary is None:
        n_near = n_simulations // 2 if near_simulations is None else int(near_simulations)
        add_summary(est, vectors, profiles, work, n_near=n_near, near_width=near_width, seed=seed, workers=workers,
                    shard_size=shard_size, config=summary_cfg, progress=progress, log=log)
    est.meta.update(n_simulations=int(len(u)), seed=int(seed), simulation_seconds=t_sim, command=command,
                    training={"config": train_cfg.to_dict(), "device": str(dev), **logs}, sbc={})
    if temperature_truths:
        choose_temperature(est, temperature_truths, seed=child_seed(seed, "temperature"), workers=workers,
                           progress=progress, log=log)
    est.save(out)  # usable now; rewritten with its SBC figures below
    if sbc_truths:
        est.meta["sbc"] = estimator_sbc(est, sbc_truths, seed=child_seed(seed, "sbc"), workers=workers,
                                        route_truths=sbc_route_truths, route_settings=route_settings,
                                        specimens=sbc_specimens if sbc_route_truths else 0, estimator_path=out,
                                        progress=progress, log=log)
        adopt_route_table(est)
    est.meta["job_seconds"] = time.perf_counter() - t0
    est.save(out)
    log(f"estimator written to {out} ({time.perf_counter() - t0:.0f} s in all)")
    return est


def choose_temperature(est: AmortizedEstimator, n: int, *, seed, workers: int = 1, progress=None,
                       log=print) -> dict:
    """Choose ``est``'s temperature on n fresh prior drones (:func:`.temperature.fit_temperature`)
    and state it in the file's meta (``temperature``, ``temperature_fit``); returns the fit."""
    vectors, profiles = sbc_data(est.spec, n, seed, workers)
    log(f"  choosing the amortized posterior's temperature on {n} fresh drones")
    fit = fit_temperature(est, est.label_free.quantities(vectors), profiles, seed=seed, progress=progress, log=log)
    est.meta.update(temperature=fit["temperature"], temperature_fit=fit)
    log(f"  temperature {fit['temperature']:g} ({'passes the gate' if fit['passed'] else 'none passes the gate'} "
        f"on those drones)")
    return fit


def check_start(start: AmortizedEstimator, spec: SimulationSpec, net_cfg: NetConfig) -> None:
    """ValueError naming the first meta field in which ``start``'s simulations or networks
    differ from ``spec`` and ``net_cfg`` (a training cannot start from its weights)."""
    for what, mine, theirs in (("spec", spec.to_dict(), start.spec.to_dict()),
                               ("net", net_cfg.to_dict(), start.net_cfg.to_dict())):
        for key in mine:
            if mine[key] != theirs.get(key):
                raise ValueError(f"meta.json field '{what}.{key}' is {theirs.get(key)!r}; this training needs "
                                 f"{mine[key]!r}")


def started_from(start: AmortizedEstimator, spec: SimulationSpec, net_cfg: NetConfig, device,
                 keep_summary: bool = True) -> AmortizedEstimator:
    """A copy of ``start``'s networks (on ``device``) to train further, its summary
    likelihood kept when ``keep_summary`` (:func:`check_start` first)."""
    check_start(start, spec, net_cfg)
    summary = start.summary if keep_summary else None
    meta = {"summary": start.meta["summary"]} if summary is not None else None
    return AmortizedEstimator(spec, net_cfg, copy.deepcopy(start.posterior).to(device),
                              copy.deepcopy(start.ratio).to(device), meta=meta, summary=summary)


def sbc_data(spec: SimulationSpec, n: int, seed, workers: int = 1):
    """Fresh drones for SBC: (vectors (n, 13E), profiles (n, 5, L); fewer measurements
    when the estimator takes fewer)."""
    from concurrent.futures import ProcessPoolExecutor

    spec5 = replace(spec, n_measurements=min(SBC_MEASUREMENTS, spec.n_measurements))
    chunks = np.array_split(np.arange(n), max(1, min(workers, n)))
    seeds = seed_sequence(seed).spawn(len(chunks))
    if workers > 1 and len(chunks) > 1:
        with ProcessPoolExecutor(workers) as pool:
            parts = list(pool.map(simulate, [spec5] * len(chunks), [len(c) for c in chunks], seeds))
    else:
        parts = [simulate(spec5, len(c), s) for c, s in zip(chunks, seeds)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def estimator_sbc(est: AmortizedEstimator, n_truths: int, *, seed: int = 0, workers: int = 1, route_truths: int = 0,
                  route_settings=None, estimator_path=None, progress=None, log=print, routes=None,
                  specimens: int = 0, specimen_seed=None) -> dict:
    """SBC of the amortized route on n_truths fresh drones (5 measurements each), and
    the route table of ``routes`` (default :func:`sampled_routes`) on the first
    ``route_truths`` of them (in ``workers`` processes when ``estimator_path``, the
    estimator's file, is given), with the same routes on ``specimens`` drones like a
    user's (:func:`specimen_table`, seeded by ``specimen_seed``, default a child of
    ``seed``; without a route table, the amortized route alone on them); the table's
    default route by :func:`name_default_route`."""
    lf = est.label_free
    vectors, profiles = sbc_data(est.spec, n_truths, seed, workers)
    truths = lf.quantities(vectors)
    space = est.spec.space()
    prior_q = lf.quantities(space.vectors(space.sample_prior(4000, np.random.default_rng(seed_sequence(seed, "prior")))))

    accepted, wanted = [], None
    out = {"n_measurements": int(profiles.shape[1]),
           "amortized": run_sbc(amortized_draw(est, accepted), truths, profiles, lf.names, prior_q=prior_q, seed=seed,
                                to_unbounded=lf.to_unbounded, progress=progress, desc="SBC amortized")}
    out["amortized"]["inside_prior_share"] = float(np.mean(accepted))
    log(f"  SBC amortized: {headline(out['amortized'])}; draws inside the prior {np.mean(accepted):.3f}")
    if route_truths:
        from .diagnostics.routes import route_table
        from .settings import CalibrationSettings

        settings = route_settings or CalibrationSettings(progress=False)
        k = min(route_truths, n_truths)
        wanted = tuple(routes or sampled_routes(est))
        routes = {name: Route(name, est if estimator_path is None else estimator_path, settings)
                  for name in runs_for(est, wanted)}
        table = route_table(routes, truths[:k], profiles[:k], lf.names, to_unbounded=lf.to_unbounded, seed=seed,
                            progress=progress, workers=workers if estimator_path is not None else 1,
                            keep_draws="stacked" in wanted)
        add_stacked(est, table["rows"], wanted)
        if "stacked" in wanted:  # judged by the gate beside the routes that ran
            from .diagnostics.routes import default_route
            from .diagnostics.yardsticks import verdict

            table["rows"]["stacked"]["verdict"] = verdict(table["rows"]["stacked"])
            table["default"] = default_route(table["rows"])
        for name in table["rows"]:
            if name != "amortized":
                out[name] = table["rows"][name]
                out[name]["likelihood"] = est.likelihood_name
                log(f"  SBC {name} ({est.likelihood_name} likelihood): {headline(out[name])}; converged "
                    f"{out[name]['converged_share']:.2f}")
        from .amortized.tempered import route_knobs

        out["route_table"] = {"drones": int(k), "default": table["default"],
                              "route_settings": route_knobs(settings, est),
                              "rows": {n: trimmed_row(r) for n, r in table["rows"].items()}}
    if specimens:  # drones like a user's: the table's routes, or the amortized route alone without a table
        s_seed = child_seed(seed, "specimens") if specimen_seed is None else specimen_seed
        out["specimens"] = specimen_table(est, specimens, settings=route_settings, seed=s_seed, workers=workers,
                                          estimator_path=estimator_path, progress=progress,
                                          routes=wanted if route_truths else ("amortized",))
    if route_truths:
        name_default_route(out)
        log(f"  route table on {k} drones: default route {out['route_table']['default']} "
            f"({out['route_table']['default_by']})")
    return out


def adopt_route_table(est: AmortizedEstimator) -> None:
    """The file runs as its route table judged it (in place): ``default_route`` the table's
    default ('amortized' without a table) and ``route_settings`` the smc route's knobs the
    table ran with (kept as they were without a table)."""
    table = est.meta.get("sbc", {}).get("route_table") or {}
    est.meta["default_route"] = table.get("default") or "amortized"
    if "route_settings" in table:
        est.meta["route_settings"] = dict(table["route_settings"])


def name_default_route(sbc: dict) -> None:
    """Name the default route of an estimator's SBC record (in place): among the routes
    that pass the gate on the route table's prior drones, the best log score on its
    specimen drones where it has them (drones like a user's), else on the prior drones
    (:func:`mdaug.inference.diagnostics.routes.default_route`); 'amortized' when none passes.
    ``default_by`` says why: the log score that chose among several passing routes, or that
    one route alone passed."""
    from .diagnostics.routes import default_route, passing_routes

    table, spec = sbc["route_table"], sbc.get("specimens")
    best = default_route(table["rows"], spec["rows"] if spec else None)
    table["default"] = best or "amortized"
    if best is None:
        table["default_by"] = "no route passes the gate"
    elif len(passing_routes(table["rows"])) == 1:
        table["default_by"] = f"the only route that passes the gate on {table['drones']} prior drones"
    else:
        table["default_by"] = (f"log score on {spec['drones']} specimen drones" if spec else
                               f"log score on {table['drones']} prior drones")


def sampled_routes(est: AmortizedEstimator) -> tuple[str, ...]:
    """The routes a route table compares for this file: all it has (the smc route on the
    summary likelihood where the file has one, on the likelihood ratio otherwise; the
    stacked route where it states a stacking weight)."""
    from .amortized.estimator import ROUTES

    return tuple(r for r in ROUTES if r != "stacked" or est.stacking_weight is not None)


def runs_for(est: AmortizedEstimator, wanted: tuple[str, ...]) -> tuple[str, ...]:
    """The routes that run for a table of ``wanted`` routes: the stacked route is no run of
    its own but derived from the smc and amortized runs on the same drones
    (:func:`add_stacked`), so it brings them both."""
    for name in wanted:
        est.check_route(name)
    if "stacked" not in wanted:
        return wanted
    return tuple(dict.fromkeys([r for r in wanted if r != "stacked"] + ["amortized", "smc"]))


def add_stacked(est: AmortizedEstimator, rows: dict, wanted: tuple[str, ...]) -> None:
    """Where ``wanted`` holds the stacked route: its row (in place), derived from the full
    smc and amortized rows of the same drones with the file's stacking weight
    (:func:`mdaug.inference.diagnostics.stacking.stacked_row`; their draws, kept for its
    widths, are dropped from every row)."""
    if "stacked" in wanted:
        from .diagnostics.stacking import stacked_row

        lf = est.label_free
        rows["stacked"] = stacked_row(rows["smc"], rows["amortized"], est.stacking_weight,
                                      to_unbounded=lf.to_unbounded)
    for row in rows.values():  # the draws the mixture's widths needed are not stored
        row.pop("draws", None)
        row.pop("truths", None)


class Route:
    """A route of an estimator file as an SBC ``draw(profiles, n, seed) -> (q draws,
    converged)`` that pickles (the file is read once per process): 'amortized' (exact
    draws) or 'smc' (tempered SMC from the amortized posterior to the posterior of the
    file's likelihood), as :func:`.amortized.calibrate.calibrate_amortized` runs them."""

    _cache: dict = {}

    def __init__(self, name: str, estimator, settings=None):
        self.name, self.settings = name, settings
        self.path = None if isinstance(estimator, AmortizedEstimator) else str(estimator)
        self._est = estimator if isinstance(estimator, AmortizedEstimator) else None
        self._last = None  # (seed, profiles, target, run) of the last smc run, for its density

    def __getstate__(self):
        if self.path is None:
            raise TypeError("a Route over an estimator in memory does not pickle: give its file's path")
        return {"name": self.name, "settings": self.settings, "path": self.path, "_est": None, "_last": None}

    @property
    def est(self) -> AmortizedEstimator:
        if self._est is None:
            if self.path not in Route._cache:
                Route._cache[self.path] = AmortizedEstimator.load(self.path)
            self._est = Route._cache[self.path]
        return self._est

    def log_density(self, u: np.ndarray, y: np.ndarray, s: int) -> float:
        """The route's own normalised log density at u (d,) given profiles y, for the
        draws of ``self(y, n, s)`` (the route table's exact log score): the amortized
        posterior's on the prior's support, or, for the smc route, that of its last call's
        run (:func:`.amortized.tempered.log_density`; the same y and seed, else it runs again)."""
        from .amortized.tempered import log_density

        if self.name == "amortized":
            return amortized_draw(self.est).log_density(u, y, s)
        u = np.asarray(u, float)[None]
        if self._last is None or self._last[0] != s or self._last[1] is not y:
            self(y, 1, s)
        _, _, post, run = self._last
        return float(log_density(u, post, lambda v: self.est.log_prob_u(v, y), run)[0])

    def __call__(self, y, n, s):
        from .amortized.tempered import smc_route

        est, lf = self.est, self.est.label_free
        if self.name == "amortized":
            return amortized_draw(est)(y, n, s)
        post, run = smc_route(est, y, self.settings, s, s)
        self._last = (s, y, post, run)
        draws = run.draws()
        pick = np.random.default_rng(s).choice(len(draws), size=n, replace=len(draws) < n)
        return lf.from_unbounded(draws[pick]), run.converged


def specimen_table(est: AmortizedEstimator, n: int, *, settings=None, seed: int = 0, workers: int = 1,
                   estimator_path=None, progress=None, routes=None) -> dict:
    """Both routes on n drones drawn as the study draws new drones (the specimen model
    around the class reference, 5 measurements each): where users' drones are, not
    the prior's. Rows as the route table's (their 'outer share' and coverage are not
    SBC: the truths are not prior draws), plus the Cramer-Rao bound's median 90% width
    / truth per quantity where the file has a summary likelihood."""
    from .diagnostics.routes import run
    from .settings import CalibrationSettings

    settings = settings or CalibrationSettings(progress=False)
    lf = est.label_free
    vectors, profiles = sbc_data(replace(est.spec, near_width=1.0), n, seed, workers)
    truths = lf.quantities(vectors)
    rows = {}
    wanted = tuple(routes or sampled_routes(est))
    for name in runs_for(est, wanted):
        route = Route(name, est if estimator_path is None else estimator_path, settings)
        rows[name] = run(route, truths, profiles, lf.names, seed=seed, to_unbounded=lf.to_unbounded,
                         progress=progress, desc=f"specimens {name}",
                         workers=workers if estimator_path is not None else 1, keep_draws="stacked" in wanted)
    add_stacked(est, rows, wanted)
    out = {"drones": int(n), "near_width": 1.0, "rows": {name: trimmed_row(r) for name, r in rows.items()}}
    if "smc" in rows:
        from .amortized.tempered import route_knobs

        out["route_settings"] = route_knobs(settings, est)
    if est.summary is not None:
        from .emulator.posterior import EmulatedPosterior

        u = lf.to_unbounded(truths)
        crb = np.array([2 * 1.645 * EmulatedPosterior(est.summary, y).crb_quantities(t) for y, t in zip(profiles, u)])
        out["crb_width_over_truth"] = dict(zip(lf.names, map(float, np.median(crb / np.abs(truths), axis=0))))
    return out


def trimmed_row(summary: dict) -> dict:
    """A route table row: the gate's figures, the log score, the widths, convergence, seconds,
    and the four quantities of lowest 90% coverage ('lowest_coverage': [name, coverage] pairs,
    where the run kept its per-quantity coverage)."""
    from .diagnostics.routes import least_covered

    keep = ("outer_share", "coverage90_range", "tarp_atc", "log_score", "log_score_by", "log_score_gaussian",
            "width_over_truth", "converged_share", "n_replicates", "verdict", "exact_fail_chance", "weight",
            "derived_from")
    row = {k: summary[k] for k in keep if k in summary}
    lowest = least_covered(summary)
    if lowest:
        row["lowest_coverage"] = lowest
    row["seconds_median"] = float(np.median(summary["seconds"]))
    return row
