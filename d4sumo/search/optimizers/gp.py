"""A Gaussian process of scores over the unit box, lean enough to sit inside every proposal.

Matern 5/2 covariance with a length scale per dimension, a signal variance and a noise variance,
on scores normalised to mean 0 and standard deviation 1. The hyperparameters maximise the log
marginal likelihood (L-BFGS-B with its analytic gradient, started from the last ones learned);
between re-learnings the process is only re-conditioned (one Cholesky factorisation), and a point
with an assumed score (a constant liar's) is added in O(n^2) by extending the factor.

This is what scikit-learn's GaussianProcessRegressor computes, without its per-call kernel objects
and n x n x d gradient tensors: at 100 points in 9 dimensions it learns its hyperparameters in a few
milliseconds, where scikit-optimize's GP took ~90 ms.

With ``inducing`` = m > 0 and more than m points, the process is conditioned through m of them (the
best-scoring half and the latest half): the deterministic training conditional (DTC), whose mean still
weighs every point, in O(n m^2) to condition and O(m^2) a prediction instead of O(n^3) and O(n^2). With
m points or fewer it is the exact process. The hyperparameters are learned from ``learn_points`` points
(the best half and the latest half).

With ``fresh_start`` (``bo``'s ``gp_version = 3``) each learning climbs the likelihood twice, from the last
values learned and from fresh ones (length scales, signal and noise variance 1, scikit-optimize's start), and
keeps the likelier: the likelihood has several optima, and a climb from little noise often stops on a worse
one (d4sumo 0.2's 39 campaigns of knots from steady state, 100 scores each, learned once from the start of
version 2, noise variance 0.01, and from the fresh one: a negative log likelihood of 98.1 against 79.8 on
average, the fresh start likelier in 26 of them, less likely in 7).
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
#: added to the inducing points' covariance, relative to the signal variance: their factor then stays well
#: conditioned however close two of them are
INDUCING_JITTER = 1e-6
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

    def __init__(self, dimension: int, max_iterations: int = 50, *, inducing: int = 0, learn_points: int = LEARN_POINTS,
                 fresh_start: bool = False):
        self.dimension = dimension
        self.fresh_start = fresh_start
        self.max_iterations = max_iterations
        self.inducing = inducing
        self.learn_points = learn_points
        self.sparse = False  # conditioned through inducing points (DTC) since the last fit
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
            self._learn(*_learning_subset(Z, t, self.learn_points))
        self.Z, self.t = Z, t
        self.sparse = 0 < self.inducing < len(t)
        self._factorise_sparse() if self.sparse else self._factorise()
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

    def _factorise_sparse(self) -> None:
        """DTC through the inducing points U, in the well-conditioned form: with Kuu = Luu Luu^T and
        V = Luu^-1 Kun, A = noise I + V V^T; mean weights Luu^-T A^-1 V t; variance
        signal - |Luu^-1 k|^2 + noise |LA^-1 Luu^-1 k|^2."""
        keep = _subset(self.t, self.inducing)
        self.U = self.Z[keep]
        Kuu = self._covariance(self.U, self.U)
        Kuu[np.diag_indices_from(Kuu)] += INDUCING_JITTER * np.exp(self.theta[-2])
        self.Luu_inverse = solve_triangular(np.linalg.cholesky(Kuu), np.eye(len(keep)), lower=True)
        self.V = self.Luu_inverse @ self._covariance(self.U, self.Z)
        self.V_t = self.V @ self.t
        self._condition_sparse(self.V @ self.V.T)

    def _condition_sparse(self, VVt: np.ndarray) -> None:
        self._VVt = VVt
        A = VVt.copy()
        A[np.diag_indices_from(A)] += self.noise_variance + JITTER
        LA = np.linalg.cholesky(A)
        self.LA_inverse = solve_triangular(LA, np.eye(len(A)), lower=True)
        self.w = self.Luu_inverse.T @ cho_solve((LA, True), self.V_t)
        self._predictor = self.LA_inverse @ self.Luu_inverse  # LA^-1 Luu^-1

    def add(self, z: np.ndarray, score: float) -> None:
        """Condition on one more point with an assumed score, hyperparameters unchanged: the Cholesky
        factor gains a row (through the inducing points: A gains a rank-one term)."""
        z = np.asarray(z, float)[None, :]
        if self.sparse:
            v = self.Luu_inverse @ self._covariance(self.U, z)[:, 0]
            t = (score - self._mean) / self._scale
            self.Z, self.t = np.vstack([self.Z, z]), np.append(self.t, t)
            self.V_t = self.V_t + v * t
            self._condition_sparse(self._VVt + np.outer(v, v))
            return
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
        if self.sparse:
            Ku = self._covariance(C, self.U)
            v1, v2 = Ku @ self.Luu_inverse.T, Ku @ self._predictor.T
            var = np.maximum(np.exp(self.theta[-2]) - (v1 * v1).sum(1) + self.noise_variance * (v2 * v2).sum(1), 1e-12)
            return self._mean + self._scale * (Ku @ self.w), self._scale * np.sqrt(var)
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
        best = self._neg_log_likelihood(start, Z, t)[0]
        if np.all(np.isfinite(result.x)) and result.fun < best:
            self.theta, best = result.x, result.fun
        if self.fresh_start:  # a second climb from length scales, signal and noise variance 1: the likelier stays
            fresh = np.clip(np.zeros(self.dimension + 2), *np.array(self._bounds).T)
            result = minimize(self._neg_log_likelihood, fresh, args=(Z, t), jac=True, method="L-BFGS-B",
                              bounds=self._bounds, options={"maxiter": self.max_iterations})
            if np.all(np.isfinite(result.x)) and result.fun < best:
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


def _learning_subset(Z: np.ndarray, t: np.ndarray, points: int = LEARN_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """At most ``points`` points: the best-scoring half and the latest half (where the search is)."""
    if len(t) <= points:
        return Z, t
    keep = _subset(t, points)
    return Z[keep], t[keep]


def _subset(t: np.ndarray, points: int) -> np.ndarray:
    """The indices of the best-scoring half of ``points`` and the latest others, in order."""
    n = len(t)
    best = np.argsort(-t, kind="stable")[:points // 2]
    rest = np.setdiff1d(np.arange(n), best)[-(points - len(best)):]
    return np.sort(np.concatenate([best, rest]))
