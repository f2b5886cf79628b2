"""A Gaussian process of scores over the unit box, lean enough to sit inside every proposal.

Matern 5/2 covariance with a length scale per dimension, a signal variance and a noise variance,
on scores normalised to mean 0 and standard deviation 1. The hyperparameters maximise the log
marginal likelihood (L-BFGS-B with its analytic gradient, started from the last ones learned);
between re-learnings the process is only re-conditioned (one Cholesky factorisation), and a point
with an assumed score (a constant liar's) is added in O(n^2) by extending the factor.

This is what scikit-learn's GaussianProcessRegressor computes, without its per-call kernel objects
and n x n x d gradient tensors: at 100 points in 9 dimensions it learns its hyperparameters in a few
milliseconds, where scikit-optimize's GP took ~90 ms.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import LinAlgError, cho_solve, solve_triangular
from scipy.linalg.lapack import dpotri
from scipy.optimize import minimize
from scipy.special import ndtr

SQRT5 = np.sqrt(5.0)
#: bounds of the hyperparameters (unit box; scores normalised to standard deviation 1)
LENGTH_SCALE = (0.01, 100.0)
SIGNAL_VARIANCE = (0.01, 100.0)
NOISE_VARIANCE = (1e-6, 10.0)
#: added to the diagonal so that the factorisation never fails on (nearly) repeated points
JITTER = 1e-8
#: hyperparameters are learned from at most this many points (the best half and the latest half): each
#: likelihood evaluation costs O(n^3), and a few hundred points say little more about length scales
LEARN_POINTS = 128


_BLAS = None


def one_blas_thread():
    """A context in which BLAS runs on one thread. The GP's matrices are small: a BLAS thread pool costs
    far more than it gains there (a likelihood at 128 points took 19 ms on two threads, 0.8 ms on one)."""
    global _BLAS
    if _BLAS is None:
        from threadpoolctl import ThreadpoolController

        _BLAS = ThreadpoolController()
    return _BLAS.limit(limits=1, user_api="blas")


def _sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = a @ b.T
    d *= -2.0
    d += (a * a).sum(1)[:, None]
    d += (b * b).sum(1)[None, :]
    return np.maximum(d, 0.0, out=d)


def matern52(r: np.ndarray) -> np.ndarray:
    """(1 + sqrt5 r + 5/3 r^2) exp(-sqrt5 r), in place of temporaries (it runs on candidates x points)."""
    k = r * (5.0 / 3.0)
    k += SQRT5
    k *= r
    k += 1.0
    k *= np.exp(-SQRT5 * r)
    return k


class GaussianProcess:
    """``fit(Z, y, learn)``, then ``predict`` mean and standard deviation (in score units), and
    ``add`` points with assumed scores (kept until the next fit)."""

    def __init__(self, dimension: int, max_iterations: int = 50):
        self.dimension = dimension
        self.max_iterations = max_iterations
        # log length scales, log signal variance, log noise variance (length scales 1 as skopt's start; little noise)
        self.theta = np.concatenate([np.zeros(dimension), [0.0, np.log(1e-2)]])
        self._bounds = [tuple(np.log(LENGTH_SCALE))] * dimension + [tuple(np.log(SIGNAL_VARIANCE)),
                                                                    tuple(np.log(NOISE_VARIANCE))]

    @property
    def length_scales(self) -> np.ndarray:
        return np.exp(self.theta[:-2])

    @property
    def noise_variance(self) -> float:
        return float(np.exp(self.theta[-1]))

    def fit(self, Z: np.ndarray, y: np.ndarray, learn: bool) -> "GaussianProcess":
        Z, y = np.asarray(Z, float), np.asarray(y, float)
        self._mean = float(y.mean())
        self._scale = float(y.std()) or 1.0
        t = (y - self._mean) / self._scale
        if learn:
            self._learn(*_learning_subset(Z, t))
        self.Z, self.t = Z, t
        self._factorise()
        return self

    def _covariance(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        ls = self.length_scales
        return np.exp(self.theta[-2]) * matern52(np.sqrt(_sq_dist(A / ls, B / ls)))

    def _factorise(self) -> None:
        K = self._covariance(self.Z, self.Z)
        K[np.diag_indices_from(K)] += self.noise_variance + JITTER
        self.L = np.linalg.cholesky(K)
        self.alpha = cho_solve((self.L, True), self.t)
        # L^-1: predictions then cost one matrix product (a triangular solve per call was 3x slower)
        self.L_inverse = solve_triangular(self.L, np.eye(len(self.t)), lower=True)

    def add(self, z: np.ndarray, score: float) -> None:
        """Condition on one more point with an assumed score, hyperparameters unchanged: the Cholesky
        factor gains a row."""
        z = np.asarray(z, float)[None, :]
        k = self._covariance(self.Z, z)[:, 0]
        b = solve_triangular(self.L, k, lower=True)
        c = np.sqrt(max(np.exp(self.theta[-2]) + self.noise_variance + JITTER - b @ b, JITTER))
        n = len(self.t)
        L = np.zeros((n + 1, n + 1))
        L[:n, :n], L[n, :n], L[n, n] = self.L, b, c
        inverse = np.zeros((n + 1, n + 1))
        inverse[:n, :n], inverse[n, :n], inverse[n, n] = self.L_inverse, -(b @ self.L_inverse) / c, 1.0 / c
        self.L, self.L_inverse, self.Z = L, inverse, np.vstack([self.Z, z])
        self.t = np.append(self.t, (score - self._mean) / self._scale)
        self.alpha = cho_solve((self.L, True), self.t)

    def predict(self, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and standard deviation of the score (without noise) at the rows of C."""
        Ks = self._covariance(C, self.Z)
        mean = Ks @ self.alpha
        v = Ks @ self.L_inverse.T
        var = np.maximum(np.exp(self.theta[-2]) - (v * v).sum(1), 1e-12)
        return self._mean + self._scale * mean, self._scale * np.sqrt(var)

    def expected_improvement(self, C: np.ndarray, best: float, xi: float) -> np.ndarray:
        """Expected improvement over the score ``best`` (maximising), ``xi`` in units of the scores'
        standard deviation."""
        mean, std = self.predict(C)
        improvement = mean - best - xi * self._scale
        u = improvement / std
        return improvement * ndtr(u) + std * np.exp(-0.5 * u * u) / np.sqrt(2.0 * np.pi)

    # -- hyperparameters ---------------------------------------------------------------------------------

    def _learn(self, Z: np.ndarray, t: np.ndarray) -> None:
        start = np.clip(self.theta, *np.array(self._bounds).T)
        result = minimize(self._neg_log_likelihood, start, args=(Z, t), jac=True, method="L-BFGS-B",
                          bounds=self._bounds, options={"maxiter": self.max_iterations})
        if np.all(np.isfinite(result.x)) and result.fun < self._neg_log_likelihood(start, Z, t)[0]:
            self.theta = result.x

    @staticmethod
    def _neg_log_likelihood(theta: np.ndarray, Z: np.ndarray, t: np.ndarray) -> tuple[float, np.ndarray]:
        n, d = Z.shape
        ls, signal, noise = np.exp(theta[:d]), np.exp(theta[d]), np.exp(theta[d + 1])
        Zs = Z / ls
        r = np.sqrt(_sq_dist(Zs, Zs))
        e = np.exp(-SQRT5 * r)
        Kf = signal * (1.0 + SQRT5 * r + (5.0 / 3.0) * r * r) * e
        K = Kf.copy()
        K[np.diag_indices_from(K)] += noise + JITTER
        try:
            L = np.linalg.cholesky(K)
        except LinAlgError:
            return 1e25, np.zeros_like(theta)
        alpha = cho_solve((L, True), t)
        nll = 0.5 * t @ alpha + np.log(np.diag(L)).sum() + 0.5 * n * np.log(2.0 * np.pi)
        inverse, info = dpotri(L, lower=True)  # K^-1 from its factor, lower triangle
        if info:
            return 1e25, np.zeros_like(theta)
        inverse = np.tril(inverse) + np.tril(inverse, -1).T
        W = np.outer(alpha, alpha) - inverse  # dNLL/dK = -W / 2
        # dK/dlog(l_j) = signal * 5/3 * (1 + sqrt5 r) e^{-sqrt5 r} * (z_aj - z_bj)^2 / l_j^2
        M = W * (signal * (5.0 / 3.0) * (1.0 + SQRT5 * r) * e)
        # sum_ab M_ab (zs_aj - zs_bj)^2 = 2 (rowsum(M) . zs_j^2 - zs_j . M zs_j), M symmetric
        grad_ls = (M.sum(1) @ (Zs * Zs) - (Zs * (M @ Zs)).sum(0))
        grad = np.empty_like(theta)
        grad[:d] = -grad_ls
        grad[d] = -0.5 * (W * Kf).sum()
        grad[d + 1] = -0.5 * noise * np.trace(W)
        return float(nll), grad


def _learning_subset(Z: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At most LEARN_POINTS points: the best-scoring half and the latest half (where the search is)."""
    n = len(t)
    if n <= LEARN_POINTS:
        return Z, t
    best = np.argsort(-t, kind="stable")[:LEARN_POINTS // 2]
    rest = np.setdiff1d(np.arange(n), best)[-(LEARN_POINTS - len(best)):]
    keep = np.sort(np.concatenate([best, rest]))
    return Z[keep], t[keep]
