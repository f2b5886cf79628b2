"""d4sumo's Gaussian process (d4sumo/search/optimizers/gp.py) against scikit-learn's and against itself."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.optimize import check_grad

from d4sumo.search.optimizers.gp import GaussianProcess


def data(n=40, d=4, seed=0, noise=0.05):
    rng = np.random.default_rng(seed)
    Z = rng.random((n, d))
    return Z, np.sin(5 * Z[:, 0]) + Z[:, 1] ** 2 + noise * rng.standard_normal(n)


def sklearn_gp(theta, Z, t):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    d = Z.shape[1]
    kernel = ConstantKernel(np.exp(theta[d])) * Matern(np.exp(theta[:d]), nu=2.5) + WhiteKernel(np.exp(theta[d + 1]) + 1e-8)
    return GaussianProcessRegressor(kernel, optimizer=None, alpha=0.0).fit(Z, t)


def test_the_log_likelihood_and_its_gradient_are_scikit_learns():
    Z, y = data()
    t = (y - y.mean()) / y.std()
    theta = np.concatenate([np.log([0.3, 1.5, 0.7, 4.0]), [0.2, np.log(0.01)]])
    nll, _ = GaussianProcess._neg_log_likelihood(theta, Z, t)
    assert nll == pytest.approx(-sklearn_gp(theta, Z, t).log_marginal_likelihood_value_, rel=1e-10)
    f = lambda th: GaussianProcess._neg_log_likelihood(th, Z, t)[0]  # noqa: E731
    g = lambda th: GaussianProcess._neg_log_likelihood(th, Z, t)[1]  # noqa: E731
    assert check_grad(f, g, theta) < 1e-4 * np.linalg.norm(g(theta))


def test_predictions_are_scikit_learns_at_the_learned_hyperparameters():
    Z, y = data()
    gp = GaussianProcess(4).fit(Z, y, learn=True)
    C = np.random.default_rng(1).random((20, 4))
    mean, std = gp.predict(C)
    sk_mean, sk_std = sklearn_gp(gp.theta, Z, (y - y.mean()) / y.std()).predict(C, return_std=True)
    assert np.allclose(mean, y.mean() + y.std() * sk_mean, atol=1e-8)
    # scikit-learn's standard deviation includes the noise; ours is the latent function's
    assert np.allclose(std ** 2 + y.std() ** 2 * (gp.noise_variance + 1e-8), y.std() ** 2 * sk_std ** 2, rtol=1e-6)


def test_learning_fits_a_smooth_function_and_a_pure_noise_one():
    Z, y = data(n=60, noise=0.0)
    gp = GaussianProcess(4).fit(Z, y, learn=True)
    C = np.random.default_rng(2).random((50, 4))
    assert np.abs(gp.predict(C)[0] - (np.sin(5 * C[:, 0]) + C[:, 1] ** 2)).max() < 0.1
    assert gp.length_scales[2] > 5 * gp.length_scales[0]  # z_2 plays no part: a long length scale
    noise = GaussianProcess(4).fit(Z, np.random.default_rng(3).standard_normal(60), learn=True)
    assert noise.noise_variance > 0.3  # scores that are noise: the GP says so


def test_adding_a_point_is_refitting_with_it_at_the_same_hyperparameters():
    Z, y = data()
    gp = GaussianProcess(4).fit(Z[:-3], y[:-3], learn=True)
    grown = copy.copy(gp)
    for z, v in zip(Z[-3:], y[-3:]):
        grown.add(z, v)
    refit = copy.copy(gp)
    refit._mean, refit._scale = gp._mean, gp._scale  # add keeps the normalisation of the fit
    refit.Z, refit.t = Z, (y - gp._mean) / gp._scale
    refit._factorise()
    C = np.random.default_rng(4).random((10, 4))
    assert np.allclose(grown.predict(C), refit.predict(C), rtol=1e-9, atol=1e-10)
    assert len(gp.t) == len(Z) - 3  # the GP it was copied from is unchanged


def test_expected_improvement_is_the_closed_form():
    from scipy.stats import norm

    Z, y = data()
    gp = GaussianProcess(4).fit(Z, y, learn=True)
    C = np.random.default_rng(5).random((30, 4))
    mean, std = gp.predict(C)
    best, xi = y.max(), 0.01
    u = (mean - best - xi * y.std()) / std
    expected = (mean - best - xi * y.std()) * norm.cdf(u) + std * norm.pdf(u)
    assert np.allclose(gp.expected_improvement(C, best, xi), expected, rtol=1e-10, atol=1e-14)
    assert np.all(gp.expected_improvement(C, best, xi) >= 0)


@pytest.mark.parametrize("case", ["repeated points", "one score", "two points"])
def test_degenerate_data_neither_fails_nor_predicts_nan(case):
    Z, y = data(n=10)
    if case == "repeated points":
        Z, y = np.vstack([Z, Z]), np.concatenate([y, y])
    elif case == "one score":
        y = np.full(10, -3.0)
    else:
        Z, y = Z[:2], y[:2]
    gp = GaussianProcess(4).fit(Z, y, learn=True)
    gp.add(Z[0], y.min())
    mean, std = gp.predict(np.random.default_rng(6).random((5, 4)))
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(std)) and np.all(std > 0)
    assert np.all(np.isfinite(gp.expected_improvement(Z, y.max(), 0.01)))


def test_through_inducing_points_the_process_predicts_what_the_exact_one_does_on_a_smooth_function():
    """Issue 25: thousands of scores. Conditioned through 120 of 400 points (DTC), the mean and standard
    deviation stay close to the exact process's, hyperparameters shared."""
    rng = np.random.default_rng(0)
    Z = rng.random((400, 3))
    y = np.sin(3.0 * Z[:, 0]) + Z[:, 1] ** 2 - 0.5 * Z[:, 2]
    exact = GaussianProcess(3).fit(Z, y, learn=True)
    sparse = GaussianProcess(3, inducing=120)
    sparse.theta = exact.theta.copy()
    sparse.fit(Z, y, learn=False)
    assert sparse.sparse and not exact.sparse
    C = rng.random((200, 3))
    (m1, s1), (m2, s2) = exact.predict(C), sparse.predict(C)
    assert np.max(np.abs(m1 - m2)) < 0.05 * np.std(y)
    assert np.max(np.abs(s1 - s2)) < 0.05 * np.std(y)


def test_a_point_added_through_inducing_points_is_what_it_adds_exactly():
    """The constant liar's point, added to the DTC's V V^T as a rank-one term, equals conditioning afresh with
    it (the same inducing points, the same normalisation)."""
    rng = np.random.default_rng(1)
    Z, y = rng.random((60, 2)), rng.random(60)
    gp = GaussianProcess(2, inducing=20).fit(Z, y, learn=True)
    z = rng.random(2)
    added = copy.deepcopy(gp)
    added.add(z, 0.3)
    again = copy.deepcopy(gp)
    again.Z, again.t = np.vstack([Z, z]), np.append(gp.t, (0.3 - gp._mean) / gp._scale)
    again.V = again.Luu_inverse @ again._covariance(again.U, again.Z)
    again.V_t = again.V @ again.t
    again._condition_sparse(again.V @ again.V.T)
    C = rng.random((50, 2))
    for a, b in zip(added.predict(C), again.predict(C)):
        assert np.allclose(a, b, rtol=1e-8, atol=1e-10)
    assert added.predict(z[None])[1][0] < gp.predict(z[None])[1][0]  # less uncertain where it was added


def test_a_fresh_start_keeps_the_likelier_hyperparameters():
    """gp_version 3: learning climbs from the last values and from length scales, signal and noise variance 1, and
    keeps the likelier, never a less likely one than the climb from the last values alone; where that climb stops on
    a worse optimum (seed 14: an interpolating one), the fresh start finds a better one."""
    for seed in range(20):
        rng = np.random.default_rng(seed)
        Z = rng.random((50, 9))
        y = np.where(Z[:, 0] > 0.5, 1.0, 0.0) * (Z[:, 1] - 0.5) + 0.3 * rng.standard_normal(50)
        t = (y - y.mean()) / y.std()
        warm, fresh = GaussianProcess(9).fit(Z, y, learn=True), GaussianProcess(9, fresh_start=True).fit(Z, y, learn=True)
        warm_nll = GaussianProcess._neg_log_likelihood(warm.theta, Z, t)[0]
        fresh_nll = GaussianProcess._neg_log_likelihood(fresh.theta, Z, t)[0]
        assert fresh_nll <= warm_nll
        if seed == 14:
            assert fresh_nll < warm_nll - 5.0
