"""The smc route's moves across the golf course (inference/amortized/redraw.py) and the
label-free map's Jacobian they lean on: exact against finite differences, and each move
leaves a known target invariant (a move that gets its correction wrong drifts)."""
import numpy as np
import pytest

from mdaug.generator import load_reference
from mdaug.inference.amortized.redraw import EngineSwap, LineMove, QuantityRedraw
from mdaug.inference.amortized.target import DroneSpace, LabelFree
from mdaug.inference.samplers.tempering import de_sweep
from mdaug.inference.space.priors import Priors


def _label_free(cls):
    ref = load_reference(cls)
    pr = Priors.from_reference(ref)
    return DroneSpace(ref.n_engines, pr), LabelFree(ref.n_engines, pr, ref.to_array())


@pytest.mark.parametrize("cls", ["HELI", "QUAD"])
def test_log_jacobian_is_the_log_determinant_of_the_map(cls):
    _, lf = _label_free(cls)
    u = np.random.default_rng(0).normal(size=(3, lf.dim))
    step = 1e-6 * np.eye(lf.dim)
    numeric = [np.linalg.slogdet((lf.from_unbounded(x + step) - lf.from_unbounded(x - step)).T / 2e-6)[1] for x in u]
    np.testing.assert_allclose(lf.log_jacobian(u), numeric, atol=1e-5)


def test_ordered_is_the_image_of_the_map():
    _, lf = _label_free("QUAD")
    q = lf.from_unbounded(np.random.default_rng(1).normal(size=(50, lf.dim)))
    assert lf.ordered(q).all()
    swapped = q.copy()
    swapped[:, [1, 2]] = swapped[:, [2, 1]]  # two lines of engine 0 out of order
    rising = q.copy()
    rising[:, lf.gamma_columns[1]] = rising[:, lf.gamma_columns[0]] + 0.1  # lnG[2] above lnG[1]
    big = q.copy()
    big[:, 5] = lf.a_max
    assert not lf.ordered(swapped).any() and not lf.ordered(rising).any() and not lf.ordered(big).any()


def _metropolis(move, log_target, u, rng, steps):
    accepted = []
    for _ in range(steps):
        prop, corr = move(u, rng)
        ok = np.log(rng.uniform(size=len(u))) < log_target(prop) - log_target(u) + corr
        u[ok] = prop[ok]
        accepted.append(ok.mean())
    return u, float(np.mean(accepted))


@pytest.mark.parametrize("kind", ["quantity", "line"])
@pytest.mark.parametrize("cls", ["HELI", "QUAD"])
def test_redraw_moves_leave_the_target_invariant(cls, kind):
    """A Gaussian target in u (sd 0.3), its kernel-density sources one sd off-centre and
    wider: started at the target, 2,000 particles keep its mean and spread after the move
    alone. With the move's density ratio and Jacobian dropped the means drift by 0.05-0.07
    towards the sources (HELI, both moves); kept, by under 0.01."""
    space, lf = _label_free(cls)
    rng = np.random.default_rng(2)
    u_prior = lf.to_unbounded(lf.quantities(space.vectors(space.sample_prior(400, rng))))
    mu, sd = np.median(u_prior, axis=0), 0.3
    sources = [mu + sd + 1.5 * sd * rng.normal(size=(300, lf.dim)), u_prior]
    move = (QuantityRedraw if kind == "quantity" else LineMove)(lf, sources, [0.9, 0.1])
    u = mu + sd * rng.normal(size=(2000, lf.dim))
    u, acc = _metropolis(move, lambda v: -0.5 * np.sum(((v - mu) / sd) ** 2, axis=1), u, rng, 60)
    assert acc > 0.02
    assert np.all(np.abs(u.mean(0) - mu) < 0.03)
    np.testing.assert_allclose(u.std(0), sd, rtol=0.1)
    assert lf.ordered(lf.from_unbounded(u)).all()


def test_engine_swap_crosses_between_brightness_labellings():
    """A target with two modes that differ by which of engines 0 and 1 holds which lines
    (equal weight): particles started in one mode end half in each, and the swap keeps
    volume (its correction is 0, the map's Jacobian equal at both ends)."""
    space, lf = _label_free("QUAD")
    rng = np.random.default_rng(4)
    m = np.median(lf.to_unbounded(lf.quantities(space.vectors(space.sample_prior(200, rng)))), axis=0)
    m[8:16] = m[:8] + 1.0  # engine 1 unlike engine 0
    swapped = m.copy()
    swapped[:8], swapped[8:16] = m[8:16], m[:8]

    def log_target(v):
        return np.logaddexp(-0.5 * np.sum(((v - m) / 0.2) ** 2, 1), -0.5 * np.sum(((v - swapped) / 0.2) ** 2, 1))

    move = EngineSwap(lf)
    u = m + 0.2 * rng.normal(size=(3000, lf.dim))
    prop, corr = move(u, rng)
    assert np.all(corr == 0) and np.allclose(lf.log_jacobian(prop), lf.log_jacobian(u))
    u, acc = _metropolis(move, log_target, u, rng, 40)
    in_swapped = np.sum((u - swapped) ** 2, 1) < np.sum((u - m) ** 2, 1)
    assert in_swapped.mean() == pytest.approx(0.5, abs=0.04)
    with pytest.raises(ValueError, match="two engines"):
        EngineSwap(_label_free("HELI")[1])


def test_redraw_moves_refuse_bad_sources():
    _, lf = _label_free("HELI")
    with pytest.raises(ValueError, match="weight"):
        QuantityRedraw(lf, [np.zeros((5, lf.dim))], [0.0])
    with pytest.raises(ValueError, match=r"\(n >= 2, 8\)"):
        QuantityRedraw(lf, [np.zeros((5, 3))], [1.0])
    with pytest.raises(ValueError, match="weight"):
        LineMove(lf, [np.zeros((5, lf.dim)), np.zeros((5, lf.dim))], [1.0])


def test_a_uniform_redraw_never_moves_a_coordinate_outside_its_box():
    """de_sweep's redraw proposes inside [lo, hi]; no redraw could bring a particle back
    outside, so one outside keeps that coordinate (the move stays reversible)."""
    rng = np.random.default_rng(3)
    theta = rng.uniform(-1, 1, size=(200, 2))
    theta[:50, 0] = 3.0  # outside the box in coordinate 0

    def flat(t):
        return np.zeros(len(t)), np.zeros(len(t))

    lp, ll = flat(theta)
    bounds = (np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    out = theta
    for _ in range(10):
        out, ll, lp, acc = de_sweep(out, ll, lp, 1.0, flat, rng, bounds=bounds, p_redraw=1.0)
    assert np.all(out[:50, 0] == 3.0)
    assert np.mean(out[50:, 0] != theta[50:, 0]) > 0.9 and acc > 0.5
