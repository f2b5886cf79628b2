"""Bayesian optimisation: ``bo`` (a Gaussian process and expected improvement over the whole box) and
``turbo`` (the same inside a trust region that follows the best point, for 10-40 dimensions).

``xi`` is in units of the scores' standard deviation (scikit-optimize's GP, ``gp_version = 1``, reads
it in score units). ``bo`` proposes ``batch_size`` points at once (5; 1 is the paper's one point per score): the constant
liar, each point proposed but not yet scored counts as the worst score seen, so their episodes can be
played side by side (and the batch spreads out: it found more distinct attacks than one at a time).
Expected improvement is maximised over random candidates and perturbations of the incumbent.

The Gaussian process is d4sumo's own (`gp.GaussianProcess`). ``gp_version = 1`` keeps
scikit-optimize's, which campaigns stored by d4sumo 0.3 and before ran with; it costs 5-20 times the
time per proposal. ``gp_version = 3`` is d4sumo's GP learning its hyperparameters from the last values
learned and from a fresh start, the likelier kept (`gp.GaussianProcess`, ``fresh_start``); 2 learns from the
last values alone, as campaigns stored since d4sumo 0.4 ran.
"""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
from scipy.spatial.distance import cdist
from scipy.stats import qmc

from ...errors import ConfigError
from .base import Optimizer
from .gp import LEARN_POINTS, GaussianProcess, one_blas_thread


#: with ``novelty``: how many more draws of candidates over the whole box, where none lies apart from the attacks found
NOVEL_DRAWS = 8


class GaussianProcessSearch(Optimizer):
    """What ``bo`` and ``turbo`` share: a Halton initial design, then expected improvement under d4sumo's
    GP, ``batch_size`` points at a time by the constant liar. Kernel hyperparameters are re-learned when
    the scores modelled have grown by ``refit_every`` or by a quarter since the last learning, whichever
    is more, and kept in between (the GP is still conditioned on every score): learning is the costly
    part, and the learned values settle as samples grow."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        self.initial_points = min(o["initial_points"], self.budget)
        self.refit_every = o["refit_every"]
        self.candidates = o["candidates"]
        self.xi = o["xi"]
        self.batch_size = o["batch_size"]
        self._initial = qmc.Halton(d=self.dimension, scramble=True, seed=self.rng)
        self._pending: list[np.ndarray] = []  # asked, not told yet (unit box)
        self._pending_modelled: list[bool] = []  # of each: whether a model proposed it
        self._told: list[np.ndarray] = []  # the points told, in the unit box
        self._gp = None
        self._fitted = 0  # the scores told when the GP was last fitted
        self._learned = 0  # the scores modelled when the hyperparameters were last learned
        self._process = GaussianProcess(self.dimension, inducing=o.get("inducing", 0), learn_points=o.get("learn_points", LEARN_POINTS),
                                        fresh_start=o.get("gp_version") == 3)
        self._run = 0  # the first sample of the current run (turbo starts new runs)

    def ready(self) -> int:
        if self.asked - self._run < self.initial_points:  # the run's initial design does not depend on scores
            return min(self.initial_points - (self.asked - self._run), self.budget - self.asked)
        return self.batch_size if not self.outstanding else 0

    def _ask(self) -> np.ndarray:
        if len(self.y) - self._run < self.initial_points:
            z = self._initial.random(1)[0]
        else:
            self._modelled()
            z = self._propose()
        self._pending.append(z)
        self._pending_modelled.append(self.asked - 1 in self.modelled)
        return self._unit_to_box(z)

    def tell(self, x: np.ndarray, score: float) -> None:
        super().tell(x, score)
        self._told.append(self._box_to_unit(self.X[-1]))
        if self._pending:
            self._pending.pop(0)  # told in the order asked
            self._pending_modelled.pop(0)

    @property
    def X_unit(self) -> list[np.ndarray]:
        return self._told

    def _candidates(self, best: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _propose(self) -> np.ndarray:
        with one_blas_thread():
            Z, scores = self._data()
            gp = self._model(Z, scores)
            if self._pending:  # a batch (constant liar): each point asked but not told scores the worst seen
                gp = copy.copy(gp)
                for z in self._pending:
                    gp.add(z, scores.min())
            cand = self._candidates(Z[int(np.argmax(scores))])
            return cand[int(np.argmax(gp.expected_improvement(cand, scores.max(), self.xi)))]

    def _data(self) -> tuple[np.ndarray, np.ndarray]:
        """The points (unit box) and scores the GP models."""
        return np.asarray(self.X_unit), np.asarray(self.y)

    def _model(self, Z: np.ndarray, scores: np.ndarray) -> GaussianProcess:
        """The GP of the scores modelled, fitted when first needed after new scores (once per batch)."""
        n = len(scores)
        if self._gp is None or self._fitted != len(self.y):
            learn = self._gp is None or n - self._learned >= max(self.refit_every, self._learned // 4)
            self._gp = self._process.fit(Z, scores, learn)
            self._fitted = len(self.y)
            if learn:
                self._learned = n
        return self._gp


class BayesianOptimization(GaussianProcessSearch):
    """Expected improvement over random candidates in the whole box and Gaussian perturbations of the
    incumbent (``local_fraction`` of them, standard deviation ``local_scale`` of the box)."""

    name = "bo"
    OPTIONS = {"initial_points": (10, 1, 10_000), "refit_every": (10, 1, 10_000), "candidates": (500, 10, 1_000_000),
               "local_fraction": (0.8, 0.0, 1.0), "local_scale": (0.1, 1e-4, 1.0), "xi": (0.01, 0.0, 10.0),
               "batch_size": (5, 1, 64), "gp_version": (2, 1, 3), "inducing": (128, 0, 100_000), "edges": (0.0, 0.0, 1.0),
               "novelty": (0.0, 0.0, 0.5)}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.local_fraction = self.options["local_fraction"]
        self.local_scale = self.options["local_scale"]
        if self.options["gp_version"] == 1:
            self._kernel = None  # the learned covariance (amplitude x Matern), without the noise term
            self._noise = 1.0  # the learned noise variance, in units of the normalised scores

    def _candidates(self, best: np.ndarray) -> np.ndarray:
        """Perturbations of ``best`` (one point, or one centre per perturbation) and points of the whole box."""
        n_local = int(self.candidates * self.local_fraction)
        local = np.clip(best + self.rng.normal(0.0, self.local_scale, size=(n_local, self.dimension)), 0.0, 1.0)
        glob = self.rng.random((self.candidates - n_local, self.dimension))
        n_edges = int(len(glob) * self.options["edges"])
        if n_edges:  # each of their coordinates, as likely as not, held at a bound: pedals floored or released
            held = self.rng.random((n_edges, self.dimension)) < 0.5
            glob[:n_edges] = np.where(held, self.rng.integers(0, 2, size=(n_edges, self.dimension)), glob[:n_edges])
        return np.vstack([local, glob])

    @classmethod
    def resolve_together(cls, options: dict) -> dict:
        if options["novelty"] and options["gp_version"] == 1:
            raise ConfigError(f"search.{cls.name}.novelty", options["novelty"],
                              "0 with gp_version = 1 (scikit-optimize's GP, as d4sumo 0.3 ran it, knew no novelty)")
        return options

    def _propose(self) -> np.ndarray:
        if self.options["gp_version"] == 1:
            return self._propose_skopt()
        if self.options["novelty"] and max(self.y) > 0.0:
            return self._propose_novel()
        return super()._propose()

    def _propose_novel(self) -> np.ndarray:
        """Once an attack succeeds, with ``novelty`` = r: another attack, distinct from every one found. Each proposal
        lies farther than r (of each parameter's range) from every success and every point pending, in some
        parameter, as `results.analysis.distinct_count` counts attacks distinct; it is the candidate of most
        expected improvement over a score of 0 (a success, not a better one: the best needs no improving), among
        perturbations of the successes (``local_fraction``, each of one drawn at random) and points of the whole box;
        where none lies apart, up to `NOVEL_DRAWS` more draws of the whole box, and where none of those does either
        (attacks all over the box at this radius), the best of all."""
        radius = self.options["novelty"]
        with one_blas_thread():
            Z, scores = self._data()
            gp = self._model(Z, scores)
            if self._pending:  # a batch (constant liar), as BO's
                gp = copy.copy(gp)
                for z in self._pending:
                    gp.add(z, scores.min())
            found = Z[scores > 0.0]
            taken = np.vstack([found, *self._pending]) if self._pending else found
            cand = self._candidates(found[self.rng.integers(len(found), size=int(self.candidates * self.local_fraction))])
            # distinct: farther than the radius from every attack taken, in some parameter (Chebyshev)
            apart = np.all(cdist(cand, taken, "chebyshev") > radius, axis=1)
            for _ in range(NOVEL_DRAWS):  # attacks all around: more points of the whole box, until one lies apart
                if apart.any():
                    break
                cand = self.rng.random((self.candidates, self.dimension))
                apart = np.all(cdist(cand, taken, "chebyshev") > radius, axis=1)
            if apart.any():  # (none: the box holds hardly a point apart at this radius; the best of all, then)
                cand = cand[apart]
            return cand[int(np.argmax(gp.expected_improvement(cand, 0.0, self.xi)))]

    # -- scikit-optimize's GP (gp_version 1): the proposals of campaigns stored by d4sumo 0.3 and before ---

    def _skopt_model(self):
        n = len(self.y)
        if self._gp is None or self._fitted != n:
            # re-learn the hyperparameters at the first fit and each time refit_every more were told
            relearn = self._kernel is None or ((n - self.initial_points) // self.refit_every
                                               > (self._fitted - self.initial_points) // self.refit_every)
            gp = self._fit(np.asarray(self.X_unit), np.asarray(self.y), relearn)
            self._kernel = gp.kernel_.k1
            self._noise = float(gp.noise_) if gp.noise_ is not None else self._noise
            self._gp, self._fitted = gp, n
        return self._gp

    def _propose_skopt(self) -> np.ndarray:
        from skopt.acquisition import gaussian_ei

        gp, scores = self._skopt_model(), np.asarray(self.y)
        if self._pending:
            lies = np.full(len(self._pending), scores.min())
            gp = self._fit(np.vstack([self.X_unit, self._pending]), np.concatenate([scores, lies]), relearn=False)
        Z = np.asarray(self.X_unit)
        cand = self._candidates(Z[int(np.argmax(self.y))])
        # skopt minimises: the GP models -score
        ei = gaussian_ei(cand, gp, y_opt=float(np.min(-scores)), xi=self.xi)
        return cand[int(np.argmax(ei))]

    def _fit(self, Z: np.ndarray, scores: np.ndarray, relearn: bool):
        """A GP of -score over the unit box; its hyperparameters re-learned, or the learned ones kept."""
        from skopt.learning import GaussianProcessRegressor
        from skopt.learning.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

        kernel = self._kernel
        if kernel is None:
            kernel = ConstantKernel(1.0, (0.01, 1000.0)) * Matern(
                length_scale=np.ones(self.dimension), length_scale_bounds=(0.01, 100.0), nu=2.5
            )
        # The noise term is explicit, so that between re-learnings the GP keeps the learned noise
        # (skopt zeroes the white kernel in kernel_ after a fit, for noise-free predictions).
        noise = WhiteKernel(noise_level=float(np.clip(self._noise, 1e-5, 1e5)), noise_level_bounds=(1e-5, 1e5))
        gp = GaussianProcessRegressor(
            kernel=kernel + noise,
            normalize_y=True,
            noise="gaussian",
            n_restarts_optimizer=0,
            optimizer="fmin_l_bfgs_b" if relearn else None,
            random_state=int(self.rng.integers(2**31 - 1)) if relearn else 0,
        )
        with warnings.catch_warnings():  # hyperparameters at their bounds are expected early on
            warnings.simplefilter("ignore")
            gp.fit(Z, -scores)
        return gp


class TrustRegionBO(GaussianProcessSearch):
    """TuRBO-1 (Eriksson et al., NeurIPS 2019): Bayesian optimisation inside a trust region, for 10-40
    dimensions where a GP of the whole box learns little from a few hundred samples.

    The region is a box around the best point of the current run, its sides in proportion to the GP's
    length scales (volume ``length``^d of the unit box). After each batch it doubles (to
    ``length_max``) after ``success_tolerance`` batches in a row that improved the best score, and halves
    after ``failure_tolerance`` (0: ceil(max(4, d) / batch_size)) that did not. Below ``length_min`` the
    run restarts from a new initial design, forgetting the old run's points (its best stays stored).
    Candidates perturb each coordinate of the centre with probability min(1, 20/d); expected improvement
    under a GP of the run's points picks among them, a batch by the constant liar.
    """

    name = "turbo"
    OPTIONS = {"initial_points": (10, 1, 10_000), "refit_every": (10, 1, 10_000), "candidates": (500, 10, 1_000_000),
               "xi": (0.01, 0.0, 10.0), "batch_size": (5, 1, 64), "length_init": (0.8, 1e-3, 2.0),
               "length_min": (0.5 ** 7, 1e-6, 1.0), "length_max": (1.6, 1e-3, 2.0), "success_tolerance": (3, 1, 1000),
               "failure_tolerance": (0, 0, 1000)}

    @staticmethod
    def resolve_together(options: dict) -> dict:
        if not options["length_min"] < options["length_init"]:
            raise ConfigError("search.turbo.length_min", options["length_min"],
                              f"below length_init ({options['length_init']}): else every batch restarts the search")
        if not options["length_init"] <= options["length_max"]:
            raise ConfigError("search.turbo.length_max", options["length_max"], f"at least length_init ({options['length_init']})")
        return options

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        self.failure_tolerance = o["failure_tolerance"] or math.ceil(max(4, self.dimension) / self.batch_size)
        self.restarts = 0
        self._start_run()

    def _start_run(self) -> None:
        self.length = self.options["length_init"]
        self._run = len(self.X)  # the first sample of the current run
        self._successes = self._failures = 0
        self._judged = len(self.X)  # samples up to here have moved the region already
        self._gp, self._learned = None, 0  # a new run learns its GP afresh, as TuRBO does
        self._process = GaussianProcess(self.dimension)

    def tell(self, x: np.ndarray, score: float) -> None:
        super().tell(x, score)
        told = len(self.y)
        if self.outstanding == 0 and self._judged - self._run >= self.initial_points and told > self._judged:
            self._judge(self.y[self._judged:told])
        if self.outstanding == 0 and told - self._run >= self.initial_points:
            self._judged = told

    def _judge(self, batch: list[float]) -> None:
        """Grow or shrink the region after a batch; restart below length_min."""
        best = max(self.y[self._run:self._judged])
        if max(batch) > best + 1e-3 * abs(best):
            self._successes, self._failures = self._successes + 1, 0
        else:
            self._successes, self._failures = 0, self._failures + 1
        if self._successes == self.options["success_tolerance"]:
            self.length, self._successes = min(2.0 * self.length, self.options["length_max"]), 0
        elif self._failures == self.failure_tolerance:
            self.length, self._failures = self.length / 2.0, 0
        if self.length < self.options["length_min"]:
            self.restarts += 1
            self._start_run()

    def _data(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.X_unit[self._run:]), np.asarray(self.y[self._run:])

    def _candidates(self, centre: np.ndarray) -> np.ndarray:
        # TuRBO's bounds on the length scales: a dimension the GP found irrelevant (a length scale of
        # 100) must not squeeze the others' sides to nothing
        weights = np.clip(self._process.length_scales, 0.005, 2.0)
        weights = weights / np.exp(np.mean(np.log(weights)))  # volume length^d (a product would underflow)
        lower = np.clip(centre - weights * self.length / 2.0, 0.0, 1.0)
        upper = np.clip(centre + weights * self.length / 2.0, 0.0, 1.0)
        points = lower + (upper - lower) * self.rng.random((self.candidates, self.dimension))
        perturb = self.rng.random((self.candidates, self.dimension)) <= min(1.0, 20.0 / self.dimension)
        untouched = ~perturb.any(axis=1)
        perturb[untouched, self.rng.integers(self.dimension, size=int(untouched.sum()))] = True
        return np.where(perturb, points, centre)
