"""Optimisers on cheap functions: no SUMO, no simulation."""

from __future__ import annotations

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.optimizers import OPTIMIZERS, CrossEntropy, make_optimizer

LOWER, UPPER = -np.ones(9), np.ones(9)
TARGET = np.random.default_rng(2024).uniform(-0.8, 0.8, 9)


def bowl(x):
    return -float(np.sum((np.asarray(x) - TARGET) ** 2))


def best_of(name, seed, budget=100, f=bowl):
    opt = make_optimizer(name, LOWER, UPPER, budget=budget, rng=np.random.default_rng(seed))
    best = -np.inf
    for _ in range(budget):
        x = opt.ask()
        assert np.all(x >= LOWER) and np.all(x <= UPPER)
        y = f(x)
        opt.tell(x, y)
        best = max(best, y)
    return best


@pytest.mark.parametrize("name", ["bo", "ce"])
def test_bo_and_ce_find_the_maximum_of_a_9d_function_far_better_than_random(name):
    random = np.mean([best_of("random", s) for s in range(3)])
    found = np.mean([best_of(name, s) for s in range(3)])
    assert found > random + 0.5, (found, random)  # random's best is around -1.5
    if name == "bo":
        assert found > -0.2, found  # close to the optimum 0


@pytest.mark.parametrize("name", OPTIMIZERS)
def test_one_seed_repeats_the_same_asks(name):
    def asks(seed):
        opt = make_optimizer(name, LOWER, UPPER, budget=30, rng=np.random.default_rng(seed))
        out = []
        for _ in range(30):
            x = opt.ask()
            opt.tell(x, bowl(x))
            out.append(x)
        return np.array(out)

    assert np.array_equal(asks(5), asks(5))
    assert not np.array_equal(asks(5), asks(6))


def test_cross_entropy_refits_its_distribution_on_the_elite():
    ce = CrossEntropy(LOWER, UPPER, 100, np.random.default_rng(0), batch_size=20, elite_fraction=0.2, smoothing=0.7)
    start_std, start_distance = ce.std.copy(), np.linalg.norm(ce.mean - TARGET)
    scores = []
    for _ in range(100):
        x = ce.ask()
        scores.append(bowl(x))
        ce.tell(x, scores[-1])
    assert ce.elite_count == 4
    assert np.all(ce.std < 0.7 * start_std)  # the distribution concentrated
    assert np.linalg.norm(ce.mean - TARGET) < 0.7 * start_distance  # ... towards the optimum
    assert np.mean(scores[80:]) > np.mean(scores[:20]) + 0.5  # later batches are better


def test_cross_entropy_samples_stay_in_the_box_near_its_edges():
    ce = CrossEntropy(LOWER, UPPER, 10, np.random.default_rng(1))
    ce.mean = UPPER.copy()  # mass at the corner: truncation must keep samples inside
    for _ in range(50):
        x = ce.ask()
        assert np.all(x <= UPPER) and np.all(x >= LOWER)


def test_unknown_optimizer_lists_the_allowed_ones():
    with pytest.raises(ConfigError, match="bo, ce, random, halton"):
        make_optimizer("annealing", LOWER, UPPER, budget=10, rng=np.random.default_rng(0))
