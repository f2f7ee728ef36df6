"""Speed against error of the study's stages, measured in the run (1 thread).

* generator: f(x) in float64 and float32 (profiles/s; max |difference| from float64);
* likelihood: the marginal likelihood's cost per evaluation against the number of
  simulated acquisitions O, and its Monte Carlo error (rms over bins of the spread of
  the model mean across common-random-number seeds, peak = 1);
* chain path: the literal chain against the reduced computation on the same draws
  (ms per profile; max |difference| of peak-normalised profiles, ADC off).

Calibration and training times come from the stages themselves (the report puts
them beside their figures: chain length over tau, balanced accuracy).
"""
from __future__ import annotations

import time

import numpy as np


def _timed(fn, repeat: int = 3):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def stage_speed(acquisition, quick: bool = False) -> dict:
    from ..generator import SigmaPAugmenter, load_reference, profiles
    from ..generator.chain import SceneConfig, render_through_chain
    from ..generator.synthetic import SyntheticDraws

    rows = []
    x = SigmaPAugmenter("QUAD", 0.2, random_state=0).sample_params(300 if quick else 2000)
    ref = None
    for dtype in ("float64", "float32"):
        sec, prof = _timed(lambda: profiles(x, dtype=dtype), 1 if quick else 3)
        ref = prof if ref is None else ref
        rows.append({"stage": "generator", "setting": f"f(x) QUAD {dtype}", "seconds": sec,
                     "rate": f"{len(x) / sec:,.0f} profiles/s", "error": float(np.max(np.abs(prof - ref))),
                     "error_metric": "max |profile - float64| (peak = 1)"})
    heli = load_reference("HELI").to_array()
    carrier, noise = np.full((1, 5), 0.1), np.full((1, 5), -45.0)
    offset = np.zeros((1, 5))
    big = SyntheticDraws(acquisition, 1, n_acquisitions=64 if not quick else 16, ramps_drawn=8, seed=99)
    mu_ref = big.profiles(heli[None], carrier, noise, offset, stride=8)[0].mean(axis=1)
    for o in ((4, 8) if quick else (4, 8, 16, 32)):
        mus, secs = [], []
        for seed in range(3 if quick else 6):
            draws = SyntheticDraws(acquisition, 1, n_acquisitions=o, ramps_drawn=8, seed=seed)
            sec, p = _timed(lambda: draws.profiles(np.repeat(heli[None], 16, 0), np.repeat(carrier, 16, 0),
                                                   np.repeat(noise, 16, 0), np.repeat(offset, 16, 0), stride=8), 1)
            secs.append(sec / 16)
            mus.append(p[0].mean(axis=1))
        err = float(np.sqrt(np.mean((np.array(mus) - mu_ref) ** 2)))
        rows.append({"stage": "likelihood", "setting": f"marginal, O = {o} acquisitions x 8 ramps (HELI, 5 meas.)",
                     "seconds": float(np.median(secs)), "rate": f"{1e3 * np.median(secs):.2f} ms / evaluation",
                     "error": err, "error_metric": "rms Monte Carlo error of the model mean (peak = 1)"})
    scene = SceneConfig.clean(n_clutter=6).with_acquisition(ramps=acquisition.ramps)
    xs = np.repeat(heli[None], 4 if quick else 16, axis=0)
    t_lit, lit = _timed(lambda: render_through_chain(xs, scene, random_state=5, method="literal"), 1)
    t_red, red = _timed(lambda: render_through_chain(xs, scene, random_state=5, method="reduced"), 1 if quick else 3)
    norm = lambda p: p / p.max(axis=1, keepdims=True)  # noqa: E731
    err = float(np.max(np.abs(norm(lit.profiles.astype(float)) - norm(red.profiles.astype(float)))))
    for name, t in (("literal chain", t_lit), ("reduced chain", t_red)):
        rows.append({"stage": "chain path", "setting": f"{name}, HELI, K = {acquisition.ramps}", "seconds": t,
                     "rate": f"{1e3 * t / len(xs):.2f} ms / profile", "error": 0.0 if name.startswith("literal") else err,
                     "error_metric": "max |reduced - literal| on the same draws (peak = 1, ADC off)"})
    return {"rows": rows}
