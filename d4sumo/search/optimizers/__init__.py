"""Optimisers with one ask/tell interface. They maximise a score over a box and know nothing else.

    opt = make_optimizer("bo", lower, upper, budget=100, rng=np.random.default_rng(seed))
    x = opt.ask(); opt.tell(x, score)

- ``random``: uniform samples in the box.
- ``halton``: a scrambled Halton sequence (low discrepancy), scaled to the box.
- ``ce``: cross-entropy: sample a batch from independent truncated normals, keep the elite quantile
  (ties included), refit mean and standard deviation with smoothing, widened by a little noise so that
  a plateau of nearly equal scores does not collapse it; a batch that is all one plateau leaves the
  distribution as it was. ``noise_fraction = 0`` is ce as d4sumo 0.4 and before ran it.
- ``ce-bucket``: VerifAI's cross-entropy over buckets, the sampler the paper ran, for comparison.
- ``cmaes``: CMA-ES (pycma) with restarts and a growing population (IPOP).
- ``bo``: Bayesian optimisation: a Gaussian process (Matern 5/2 with a length scale per dimension,
  learned noise; d4sumo's own, `gp.py`) and expected improvement, maximised over random candidates and
  perturbations of the incumbent. It proposes ``batch_size`` points at once (5; 1 is the paper's one
  point per score) by the constant liar. ``gp_version = 1`` runs scikit-optimize's GP instead, as
  campaigns stored by d4sumo 0.3 and before did (5-20 times BO's own time).
- ``auto``: ``bo`` and exploring arms as one portfolio over one GP: once BO's points stop improving
  (``patience``), each point explores with a probability that moves to whichever arms improve the best
  score (`portfolio`). The
  exploring arms propose held inputs (pieces held at a bound or a value) and piece moves on the
  incumbent; on a plateau, where BO narrows around an arbitrary incumbent, they carry it. Once a score
  is positive (an attack found), every point is BO's.
- ``turbo``: TuRBO-1, the same inside a trust region that follows the best point, grows on successes,
  shrinks on failures and restarts when it collapses: for 10-40 dimensions.

``ready()`` says how many points an optimiser proposes before it is told a score: a cross-entropy
generation, a CMA-ES population, any number of random or Halton points, BO's and TuRBO's initial
designs and their constant-liar batches. The campaign always asks for that many at once and plays them
side by side (`batch`), so how many episodes share a SUMO changes no proposal.

Every optimiser draws from the Generator it is given: one seed reproduces a campaign exactly. Options
(``OPTIONS`` of each class) come from a config's ``[search.<optimizer>]`` table, validated by
`resolve_options`. A score that is NaN or infinite counts as the worst score told so far: one failed
sample never breaks later proposals. No optimiser proposes past its budget.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ... import ledger
from ...errors import ConfigError
from .base import INDEPENDENT_BATCH, Optimizer, check_options
from .bayes import BayesianOptimization, TrustRegionBO
from .cmaes import CMAES
from .crossentropy import BucketCrossEntropy, CrossEntropy
from .portfolio import Portfolio
from .sampling import Halton, RandomSearch

OPTIMIZERS = ("bo", "auto", "turbo", "ce", "ce-bucket", "cmaes", "random", "halton")

_FACTORIES: dict[str, Callable[..., Optimizer]] = {
    "bo": BayesianOptimization,
    "auto": Portfolio,
    "turbo": TrustRegionBO,
    "ce": CrossEntropy,
    "ce-bucket": BucketCrossEntropy,
    "cmaes": CMAES,
    "random": RandomSearch,
    "halton": Halton,
}


def _as_earlier_versions_ran(name: str) -> tuple[dict[str, float], ...]:
    """The ledger's sets of ``name``'s options as each earlier release ran them, newest first, each distinct set
    once, each without the options that setting changes nothing (at today's default, or implied by the others:
    auto's version 1 has no stalls)."""
    sets: list[dict[str, float]] = []
    for then in ledger.as_ran(f"search.{name}"):
        changed = dict(then)
        for key in then:
            others = {k: v for k, v in changed.items() if k != key}
            if _FACTORIES[name].resolve_together(check_options(name, _FACTORIES[name].OPTIONS, others))[key] == then[key]:
                changed = others
        if changed and changed not in sets:
            sets.append(changed)
    return tuple(sets)


#: how each optimiser ran in earlier d4sumo versions, newest first: the options that give back its proposals,
#: from the ledger (bo in 0.7 and before: the exact GP however many scores; in 0.3: scikit-optimize's GP; in
#: 0.2 also one point per score; ce in 0.4 and before: no noise; auto in 0.10.1: held sampling across signals;
#: in 0.10 also exploring from the design on; in 0.9 also no suffix moves; in 0.8 also no piece moves through
#: stalls; in 0.7 uniform exploration)
EARLIER_OPTIONS: dict[str, tuple[dict[str, float], ...]] = {
    name: sets for name in _FACTORIES if (sets := _as_earlier_versions_ran(name))}


#: the optimiser a campaign runs when none is named, and the one earlier d4sumo versions ran instead
#: (bo, in 0.7 and before): a database of campaigns run by default then is found again by it
DEFAULT_OPTIMIZER, EARLIER_DEFAULT_OPTIMIZER = "auto", "bo"


def as_set_flags(name: str, options: dict) -> str:
    """``--set search.<name>.<key>=<value>`` for each option."""
    return " ".join(f"--set search.{name}.{k}={v}" for k, v in options.items())


def stored_options(name: str, options: dict) -> dict:
    """The options as a campaign's definition holds them: without the options added later where they hold the
    value earlier campaigns ran with (`ledger`)."""
    return ledger.stored(f"search.{name}", options)


def resolve_options(name: str, options: dict | None) -> dict:
    """Every option of optimiser ``name``, defaults filled in, each value checked."""
    if name not in _FACTORIES:
        raise ConfigError("search.optimizer", name, f"one of {', '.join(OPTIMIZERS)}")
    return _FACTORIES[name].resolve_together(check_options(name, _FACTORIES[name].OPTIONS, options))


def make_optimizer(name: str, lower, upper, *, budget: int, rng: np.random.Generator, options: dict | None = None,
                   signals: tuple[int, ...] | None = None) -> Optimizer:
    """``signals``: how the parameters lay out in time (`Optimizer`); the attack family's ``signals``."""
    if name not in _FACTORIES:
        raise ConfigError("optimizer", name, f"one of {', '.join(OPTIMIZERS)}")
    return _FACTORIES[name](np.asarray(lower, float), np.asarray(upper, float), budget, rng, signals=signals, **(options or {}))


__all__ = ["OPTIMIZERS", "DEFAULT_OPTIMIZER", "EARLIER_DEFAULT_OPTIMIZER", "EARLIER_OPTIONS", "INDEPENDENT_BATCH", "Optimizer", "BayesianOptimization", "BucketCrossEntropy",
           "CMAES", "CrossEntropy", "Halton", "Portfolio", "RandomSearch", "TrustRegionBO", "as_set_flags", "make_optimizer", "resolve_options", "stored_options"]
