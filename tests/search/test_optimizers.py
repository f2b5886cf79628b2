"""Optimisers on cheap functions: no SUMO, no simulation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.search.optimizers import OPTIMIZERS, CrossEntropy, make_optimizer
from d4sumo.search.optimizers.portfolio import BO, PIECE, RANDOM

from conftest import made_ahead, side_by_side
from histories import DATA, check_history, numerics, tell_history  # noqa: F401  (numerics: a fixture)

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


@pytest.mark.parametrize("name", ["bo", "auto", "turbo", "ce", "cmaes"])
def test_bo_turbo_ce_and_cmaes_find_the_maximum_of_a_9d_function_far_better_than_random(name):
    random = np.mean([best_of("random", s) for s in range(3)])
    found = np.mean([best_of(name, s) for s in range(3)])
    assert found > random + 0.5, (found, random)  # random's best is around -1.5
    if name in ("bo", "turbo"):  # close to the optimum 0 (turbo, a local search, more slowly)
        assert found > (-0.2 if name == "bo" else -0.35), found


@pytest.mark.usefixtures("numerics")
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
    ce = CrossEntropy(LOWER, UPPER, 50, np.random.default_rng(1))
    ce.mean = UPPER.copy()  # mass at the corner: truncation must keep samples inside
    for _ in range(50):
        x = ce.ask()
        assert np.all(x <= UPPER) and np.all(x >= LOWER)


def test_unknown_optimizer_lists_the_allowed_ones():
    with pytest.raises(ConfigError, match="bo, auto, turbo, ce, ce-bucket, cmaes, random, halton"):
        make_optimizer("annealing", LOWER, UPPER, budget=10, rng=np.random.default_rng(0))


@pytest.mark.parametrize("name", OPTIMIZERS)
def test_nothing_is_proposed_past_the_budget(name):
    opt = make_optimizer(name, LOWER, UPPER, budget=12, rng=np.random.default_rng(0))
    for _ in range(12):
        x = opt.ask()
        opt.tell(x, bowl(x))
    with pytest.raises(ValueError, match="budget of 12 samples is spent"):
        opt.ask()


@pytest.mark.parametrize("name", OPTIMIZERS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_nan_or_infinite_score_does_not_break_later_proposals(name, bad):
    """Regression: an errored sample told as NaN/inf made the GP's fit fail or its proposals NaN."""
    opt = make_optimizer(name, LOWER, UPPER, budget=30, rng=np.random.default_rng(0))
    for i in range(30):
        x = opt.ask()
        assert np.all(np.isfinite(x)) and np.all(x >= LOWER) and np.all(x <= UPPER)
        opt.tell(x, bad if i in (3, 12, 17) else bowl(x))
    assert all(np.isfinite(opt.y)) and opt.y[12] == min(opt.y[:12])


def test_bo_keeps_the_learned_noise_between_relearnings():
    """Regression: between re-learnings the GP was refit with noise 0 (skopt zeroes the white kernel
    in kernel_ after a fit, and the next fit reused that kernel_)."""
    rng = np.random.default_rng(3)
    opt = make_optimizer("bo", LOWER, UPPER, budget=40, rng=np.random.default_rng(0),
                         options={"refit_every": 10, "gp_version": 1})
    for i in range(25):
        x = opt.ask()
        opt.tell(x, rng.normal(0, 1.0))  # pure noise: the GP must learn a noise level
        if i == 19:  # re-learned at 20 samples, when next needed
            opt._skopt_model()
            learned = opt._noise
    assert learned > 1e-4
    assert opt._noise == learned and opt._gp.noise_ == pytest.approx(learned)


def test_optimizer_options_are_checked_and_defaults_filled():
    from d4sumo.search.optimizers import resolve_options

    assert resolve_options("ce", {"batch_size": np.int64(20)}) == {"batch_size": 20, "elite_fraction": 0.2, "smoothing": 0.7,
                                                                   "min_std_fraction": 0.02, "noise_fraction": 0.1}
    with pytest.raises(ConfigError, match="search.ce.batchsize"):
        resolve_options("ce", {"batchsize": 20})
    with pytest.raises(ConfigError, match="search.bo.xi"):
        resolve_options("bo", {"xi": float("nan")})
    with pytest.raises(ConfigError, match="random has no options"):
        resolve_options("random", {"x": 1})
    ce = make_optimizer("ce", LOWER, UPPER, budget=40, rng=np.random.default_rng(0), options={"batch_size": 20})
    assert ce.batch_size == 20 and ce.elite_count == 4


# --- ties, plateaus, the paper's bucket sampler, CMA-ES restarts -----------------------------------


def test_cross_entropy_keeps_its_distribution_on_a_plateau():
    """Regression: on a plateau of equal scores, ce refit on whichever samples came first and collapsed."""
    ce = CrossEntropy(LOWER, UPPER, 200, np.random.default_rng(0), batch_size=10)
    start_mean, start_std = ce.mean.copy(), ce.std.copy()
    for _ in range(100):
        ce.tell(ce.ask(), -3.0)  # every no-crash episode of a one-sided spec scores alike
    assert np.array_equal(ce.mean, start_mean) and np.array_equal(ce.std, start_std)


def test_cross_entropy_does_not_collapse_on_a_plateau_of_nearly_equal_scores():
    """Issue 13: in 40 dimensions ce's elite of two points per batch, picked by scores that differ only
    by noise, shrank its spread to the floor within 300 samples (below random search's rate of
    falsification on tools/bench_arch.py); the noise it adds at each refit keeps it searching."""
    lower, upper = np.zeros(40), np.ones(40)

    def spread(options):
        ce = CrossEntropy(lower, upper, 300, np.random.default_rng(0), **options)
        noise = np.random.default_rng(1)
        for _ in range(300):
            ce.tell(ce.ask(), -1.0 + 1e-9 * noise.standard_normal())
        return ce.std

    assert np.all(spread({"noise_fraction": 0.0}) <= 0.05)  # as d4sumo 0.4 ran it: collapsed to 2-5% of the range
    assert np.all(spread({}) >= 0.1)  # never narrower than the noise it adds


def test_a_ce_campaign_an_earlier_version_stored_keeps_its_identity_and_replays_without_noise():
    from d4sumo.search.campaign import Campaign
    from d4sumo.search.store import campaign_key

    new = Campaign(optimizer="ce")
    assert new.definition()["optimizer_options"]["noise_fraction"] == 0.1
    old = new.definition()
    del old["optimizer_options"]["noise_fraction"]  # d4sumo 0.4 and before had no such option
    stored = Campaign.from_definition(old)
    assert dict(stored.optimizer_options)["noise_fraction"] == 0.0
    assert campaign_key(stored.definition()) == campaign_key(old)


def test_cross_entropy_counts_every_tie_at_the_elite_threshold():
    ce = CrossEntropy(LOWER, UPPER, 20, np.random.default_rng(0), batch_size=10, elite_fraction=0.2, smoothing=1.0)
    xs = [ce.ask() for _ in range(10)]
    for i, x in enumerate(xs):  # one best, then five tied for second place, then worse
        ce.tell(x, 1.0 if i == 0 else (0.5 if i <= 5 else 0.0))
    assert np.allclose(ce.mean, np.mean(xs[:6], axis=0))


def test_bucket_cross_entropy_learns_from_counterexamples_only():
    from d4sumo.search.optimizers import BucketCrossEntropy

    opt = BucketCrossEntropy(np.zeros(2), np.ones(2), 50, np.random.default_rng(0), buckets=5, alpha=0.9)
    x = opt.ask()
    opt.tell(x, -0.5)  # not a counterexample: VerifAI's sampler does not move
    assert np.allclose(opt.dist, 0.2)
    x = opt.ask()
    opt.tell(x, 0.3)  # a counterexample: its buckets gain 1 - alpha
    bucket = np.minimum((x * 5).astype(int), 4)
    assert np.allclose(opt.dist[[0, 1], bucket], 0.9 * 0.2 + 0.1) and np.allclose(opt.dist.sum(axis=1), 1.0)


def test_cmaes_restarts_with_a_larger_population_and_never_touches_numpys_global_state():
    state = np.random.get_state()
    opt = make_optimizer("cmaes", LOWER, UPPER, budget=600, rng=np.random.default_rng(0))
    first = opt._popsize
    for _ in range(600):
        x = opt.ask()
        opt.tell(x, -1.0 if np.all(x < 0.9) else 0.0)  # a plateau almost everywhere: CMA stalls and restarts
    assert opt.restarts >= 1 and opt._popsize == first * 2 ** opt.restarts
    after = np.random.get_state()
    assert state[0] == after[0] and np.array_equal(state[1], after[1]) and state[2:] == after[2:]


@pytest.mark.usefixtures("numerics")
@pytest.mark.parametrize("name", OPTIMIZERS)
def test_an_optimisers_state_pickles_midway_and_goes_on_exactly(name):
    """Regression: CMA-ES held a lambda, so a sweep on two worker processes could not send its state."""
    import pickle

    def run(split: bool) -> list:
        opt = make_optimizer(name, np.zeros(4), np.ones(4), budget=30, rng=np.random.default_rng(5))
        asked = []
        for i in range(30):
            if split and i == 13:
                opt = pickle.loads(pickle.dumps(opt))
            x = opt.ask()
            asked.append(tuple(x))
            opt.tell(x, -float(np.sum((x - 0.3) ** 2)))
        return asked

    assert run(split=True) == run(split=False)


_HALVES = """
import pickle, sys
import numpy as np
from d4sumo.search.optimizers import make_optimizer

name, half, path = sys.argv[1], sys.argv[2], sys.argv[3]
if half == "first":
    opt, asked = make_optimizer(name, np.zeros(4), np.ones(4), budget=30, rng=np.random.default_rng(5)), []
else:
    opt, asked = pickle.load(open(path, "rb"))
for i in range(13) if half == "first" else range(13, 30):
    x = opt.ask()
    asked.append(tuple(map(float, x)))
    opt.tell(x, -float(np.sum((x - 0.3) ** 2)))
pickle.dump((opt, asked), open(path, "wb"))
"""


@made_ahead()
def halves_in_two_processes(tmp_path_factory):
    """Every optimiser's 30 asks, the first 13 in one process and the rest in another of another hash salt,
    the optimisers side by side: {name: (the two processes, the file of the state and every ask)}."""
    import os
    import subprocess
    import sys

    folder = tmp_path_factory.mktemp("halves")

    def halves(name):
        path, done = folder / f"{name}.pkl", []
        for half, salt in (("first", "1"), ("second", "2")):
            done.append(subprocess.run([sys.executable, "-c", _HALVES, name, half, str(path)], capture_output=True, text=True,
                                       env={**os.environ, "PYTHONHASHSEED": salt}, timeout=120))
            if done[-1].returncode != 0:
                break
        return done, path

    return dict(zip(OPTIMIZERS, side_by_side([lambda name=name: halves(name) for name in OPTIMIZERS])))


@pytest.mark.parametrize("name", OPTIMIZERS)
def test_an_optimisers_state_goes_on_exactly_in_another_process(name, halves_in_two_processes):
    """Regression: pycma finds the points it asked by hash(x.tobytes()), which Python salts anew in every
    process: CMA-ES carried to another worker mid-generation (a sweep's next chunk) went on differently,
    so a sweep's samples depended on how its chunks fell on its workers."""
    import pickle

    processes, path = halves_in_two_processes[name]
    assert [p.args[4] for p in processes] == ["first", "second"] and [p.returncode for p in processes] == [0, 0], processes[-1].stderr
    _, asked = pickle.load(open(path, "rb"))
    opt, alone = make_optimizer(name, np.zeros(4), np.ones(4), budget=30, rng=np.random.default_rng(5)), []
    for _ in range(30):
        x = opt.ask()
        alone.append(tuple(map(float, x)))
        opt.tell(x, -float(np.sum((x - 0.3) ** 2)))
    assert asked == alone


@pytest.mark.parametrize("name, options", [("bo", {}), ("bo", {"gp_version": 1}), ("bo", {"gp_version": 3}), ("turbo", {"failure_tolerance": 1}),
                                           ("auto", {"stall": 3})])
def test_a_bayesian_optimisers_state_pickles_inside_a_batch_and_goes_on_exactly(name, options):
    """A sweep sends the state between chunks; a chunk may end with points asked and not told."""
    import pickle

    def run(split: bool) -> list:
        opt = make_optimizer(name, np.zeros(4), np.ones(4), budget=40, rng=np.random.default_rng(5),
                             options={"initial_points": 5, **options})
        asked = []
        while opt.asked < opt.budget:
            xs = [opt.ask() for _ in range(max(1, min(opt.ready(), opt.budget - opt.asked)))]
            asked.extend(tuple(x) for x in xs)
            for i, x in enumerate(xs):
                if split and i == 1:
                    opt = pickle.loads(pickle.dumps(opt))
                opt.tell(x, -float(np.sum((x - 0.3) ** 2)))
        return asked

    assert run(split=True) == run(split=False)


def test_turbo_refuses_lengths_that_do_not_nest():
    from d4sumo.search.optimizers import resolve_options

    with pytest.raises(ConfigError, match="search.turbo.length_min.*below length_init"):
        resolve_options("turbo", {"length_min": 0.9, "length_init": 0.5})
    with pytest.raises(ConfigError, match="search.turbo.length_max.*at least length_init"):
        make_optimizer("turbo", LOWER, UPPER, budget=10, rng=np.random.default_rng(0), options={"length_max": 0.5})


def test_turbo_learns_its_gp_afresh_after_a_restart():
    opt = make_optimizer("turbo", LOWER, UPPER, budget=60, rng=np.random.default_rng(0),
                         options={"initial_points": 5, "batch_size": 2, "failure_tolerance": 1, "length_min": 0.3})
    learned = []
    real = opt._process.fit

    def spy(process):
        fit = process.fit

        def record(Z, y, learn):
            learned.append((opt._run, len(y), learn))
            return fit(Z, y, learn)
        process.fit = record

    spy(opt._process)
    real_start = opt._start_run

    def start():
        real_start()
        spy(opt._process)

    opt._start_run = start
    play_in_batches(opt, lambda x: 0.0)
    assert opt.restarts >= 2 and real is not None
    firsts = {}
    for run, n, learn in learned:
        firsts.setdefault(run, (n, learn))
    assert all(learn and n == 5 for n, learn in firsts.values()), firsts  # each run's first fit learns


@pytest.mark.usefixtures("numerics")
def test_bo_one_point_per_score_proposes_what_the_version_before_batches_proposed():
    """Campaigns stored before BO proposed in batches replay with batch_size 1 only if its proposals are
    unchanged: a campaign of d4sumo 0.2 (`histories`), told back, gets its own design and, at each of BO's
    points, the same candidates (the GP's choice among them is this machine's)."""
    asks = check_history("bo 0.2")
    assert sum(a["modelled"] for a in asks) == 15


def play_in_batches(opt, f):
    """Ask as a campaign does (a batch of ready() points, then their scores)."""
    while opt.asked < opt.budget:
        xs = [opt.ask() for _ in range(max(1, min(opt.ready(), opt.budget - opt.asked)))]
        for x in xs:
            opt.tell(x, f(x))


@pytest.mark.usefixtures("numerics")
def test_turbo_shrinks_its_trust_region_on_failures_and_restarts_from_a_new_design():
    opt = make_optimizer("turbo", LOWER, UPPER, budget=200, rng=np.random.default_rng(0),
                         options={"initial_points": 5, "batch_size": 2, "failure_tolerance": 1, "length_min": 0.1})
    lengths, runs, ready = [], [], []
    real_judge = opt._judge

    def judge(batch):
        real_judge(batch)
        lengths.append(opt.length)
        runs.append(opt._run)
        ready.append(opt.ready())

    opt._judge = judge
    play_in_batches(opt, lambda x: 0.0)  # a plateau: no batch ever improves
    assert lengths[:4] == [0.4, 0.2, 0.1, 0.8]  # halved after each failed batch; below 0.1 a new run at 0.8
    assert runs[:4] == [0, 0, 0, 5 + 4 * 2] and opt.restarts == len(lengths) // 4
    # each run opens with its own initial design of 5 points, proposed as one batch; then batches of 2
    assert ready[:4] == [2, 2, 2, 5]


@pytest.mark.usefixtures("numerics")
def test_turbo_grows_its_trust_region_on_successes_and_keeps_its_candidates_in_it():
    opt = make_optimizer("turbo", LOWER, UPPER, budget=40, rng=np.random.default_rng(1),
                         options={"initial_points": 5, "batch_size": 1, "success_tolerance": 2, "length_init": 0.2})
    count = iter(range(1000))
    play_in_batches(opt, lambda x: float(next(count)))  # every sample beats the last
    assert opt.length == 1.6  # doubled every 2 successes, up to length_max
    centre = opt._box_to_unit(opt.X[int(np.argmax(opt.y[opt._run:])) + opt._run])
    opt.length = 0.1
    cand = opt._candidates(centre)
    weights = np.clip(opt._process.length_scales, 0.005, 2.0)
    weights /= weights.mean()
    weights /= np.prod(weights) ** (1 / 9)
    assert np.all(np.abs(cand - centre) <= weights * 0.1 / 2 + 1e-12)
    assert np.all((cand != centre).any(axis=1))  # every candidate moves at least one coordinate


def test_turbo_finds_the_maximum_of_a_40d_function_where_random_search_does_not():
    target = np.random.default_rng(7).uniform(-0.5, 0.5, 40)

    def f(x):
        return -float(np.sum((x - target) ** 2))

    lower, upper = -np.ones(40), np.ones(40)
    bests = {}
    for name in ("turbo", "random"):
        opt = make_optimizer(name, lower, upper, budget=200, rng=np.random.default_rng(0))
        play_in_batches(opt, f)
        bests[name] = max(opt.y)
    assert bests["turbo"] > bests["random"] + 3.0, bests  # random's best is around -10


def _arms_played(opt, f) -> list[int]:
    """Play auto to its budget as a campaign does: the arm of every point (BO, held sampling or uniform,
    piece moves), in the order asked."""
    arms = []
    while opt.asked < opt.budget:
        xs = [opt.ask() for _ in range(max(1, min(opt.ready(), opt.budget - opt.asked)))]
        arms += opt._arms[-len(xs):]
        for x in xs:
            opt.tell(x, f(x))
    return arms


def _arms_after(f, budget=120, seed=0, **options):
    """How many points each arm of auto proposed after its initial design, and its final exploring share."""
    opt = make_optimizer("auto", LOWER, UPPER, budget=budget, rng=np.random.default_rng(seed), options=options)
    arms = _arms_played(opt, f)[opt.initial_points:]
    return [arms.count(arm) for arm in (BO, RANDOM, PIECE)], opt.random_share


@pytest.mark.usefixtures("numerics")
@pytest.mark.parametrize("version", [1, 2])
def test_auto_moves_its_budget_to_bo_where_the_model_informs(version):
    """Where BO improves the best, the exploring share falls towards its floor (0.2) and BO takes most of
    the budget; over six seeds, since which arm made an improvement depends on BO's proposals, whose last
    bits are each machine's (with OpenBLAS pinned to other kernels, one seed's share ended at 0.25 or 0.33
    where this machine's was 0.2, and BO's points of the six fell from 2.4 times the exploring ones to 2)."""
    bowl = lambda x: -float(np.sum((x - 0.3) ** 2))  # noqa: E731
    runs = [_arms_after(bowl, seed=seed, version=version, stall=0) for seed in range(6)]
    assert np.mean([share for _, share in runs]) <= 0.3
    assert sum(bo for (bo, *_), _ in runs) > 1.5 * sum(sum(explore) for (_, *explore), _ in runs)
    runs = [_arms_after(bowl, seed=seed, version=version) for seed in range(6)]  # with stalls too
    assert sum(bo for (bo, *_), _ in runs) > sum(sum(explore) for (_, *explore), _ in runs)


@pytest.mark.usefixtures("numerics")
@pytest.mark.parametrize("version, stall, expected", [(1, 25, 0.5), (2, 0, 0.5), (2, 25, 0.8)])
def test_auto_keeps_half_its_budget_exploring_on_a_plateau_and_more_once_it_stalls(version, stall, expected):
    """Nothing improves: the share stays where it started, then (held sampling, ``stall`` scores without a new
    best) goes to ``share_max``; uniform exploration (version 1) knows no stalls."""
    (bo, random, piece), share = _arms_after(lambda x: -1.0, budget=200, version=version, stall=stall)
    assert share == expected and abs((random + piece) / (bo + random + piece) - expected) < 0.1  # 3 sd of 200 draws
    assert (piece > 0) == (version == 2)


@pytest.mark.usefixtures("numerics")
def test_a_stall_turns_every_exploring_point_to_a_fresh_held_one_until_a_new_best():
    """CC4's failed runs: piece moves crept up a dead end for a thousand scores, held sampling got a tenth of
    the budget. Stalled, the exploring points are held samples at share_max; a new best ends the stall."""
    opt = make_optimizer("auto", LOWER, UPPER, budget=200, rng=np.random.default_rng(2), options={"stall": 20})
    arms_stalled = []
    while opt.asked < 150:
        xs = [opt.ask() for _ in range(max(1, opt.ready()))]
        stalled = opt.stalled
        if stalled:
            arms_stalled += opt._arms[-len(xs):]
        for x in xs:
            opt.tell(x, -1.0)
        assert stalled == (len(opt.y) - len(xs) >= 21)  # the first score was the best: 20 more without one
    assert opt.random_share == 0.8 and len(arms_stalled) > 50
    assert PIECE not in arms_stalled and 0.6 < arms_stalled.count(RANDOM) / len(arms_stalled) < 0.95
    x = opt.ask()
    opt.tell(x, -0.5)
    assert not opt.stalled and opt.random_share < 0.8


def _rising_then_flat(opt, rising: int = 40):
    """Scores that are each a new best for the first ``rising`` told, then none."""
    return lambda x: -1000.0 + len(opt.y) if len(opt.y) < rising else -1000.0


@pytest.mark.usefixtures("numerics")
@pytest.mark.parametrize("patience", [5, 12])
def test_auto_explores_once_bos_points_stop_improving(patience):
    """Every point after the design is BO's until ``patience`` of BO's points in a row bring no new best
    (its scores stopped informing); from then on the arms explore, however BO does later."""
    from d4sumo.search.optimizers import resolve_options

    opt = make_optimizer("auto", LOWER, UPPER, budget=200, rng=np.random.default_rng(4), options={"patience": patience})
    after_design = _arms_played(opt, _rising_then_flat(opt))[opt.initial_points:]
    first = next(i for i, arm in enumerate(after_design) if arm != BO)
    assert first >= 40 - opt.initial_points + patience - 1  # BO alone while every point improved, then patience more
    # then the arms explore: at share_min while BO's credits hold it down, at share_max from the stall on
    assert first < 40 - opt.initial_points + max(patience, opt.options["stall"]) + 10
    assert after_design[first:].count(BO) < 0.7 * len(after_design[first:])
    assert resolve_options("auto", {"version": 1})["patience"] == 0 and resolve_options("auto", {})["patience"] == 5


@pytest.mark.usefixtures("numerics")
def test_bo_alone_earns_no_credit_before_exploring_starts():
    """Credits say which arm improves while the arms compete: improvements BO made alone (before
    ``patience`` of its points brought nothing) do not hold the exploring share at its floor afterwards."""
    opt = make_optimizer("auto", LOWER, UPPER, budget=60, rng=np.random.default_rng(4))
    _arms_played(opt, _rising_then_flat(opt))
    assert opt._explores and opt.credits.tolist() == [1.0, 0.5, 0.5] and opt.random_share == 0.5


@pytest.mark.usefixtures("numerics")
def test_auto_leaves_every_point_to_bo_once_an_attack_is_found():
    """Exploring serves the first falsification; past a positive score BO collects attacks around it."""
    (bo, random, piece), share = _arms_after(lambda x: 1.0, budget=60)
    assert share == 0.0 and random + piece == 0 and bo == 50
    (_, random, _), share = _arms_after(lambda x: 1.0, budget=200, version=1)
    assert share == 0.5 and random > 0  # version 1 explored whatever the scores


@pytest.mark.usefixtures("numerics")
def test_auto_is_bo_point_for_point_once_its_initial_design_holds_an_attack():
    """d4sumo's campaigns: an attack among the initial design, and auto with its defaults proposes what bo does."""
    f = lambda x: 1.0 - float(np.sum((x - 0.3) ** 2)) / 100.0  # noqa: E731  (positive in the whole box)
    auto = make_optimizer("auto", LOWER, UPPER, budget=60, rng=np.random.default_rng(5))
    bo = make_optimizer("bo", LOWER, UPPER, budget=60, rng=np.random.default_rng(5))
    while bo.asked < 60:
        xs, ys = [auto.ask() for _ in range(auto.ready())], [bo.ask() for _ in range(bo.ready())]
        assert np.array_equal(np.array(xs), np.array(ys))
        for a, b in zip(xs, ys):
            auto.tell(a, f(a))
            bo.tell(b, f(b))


@pytest.mark.usefixtures("numerics")
@pytest.mark.parametrize("dimension", [1, 3, 9])
def test_auto_never_proposes_a_point_twice_while_it_explores(dimension):
    """Regression: with a few parameters held points are few (one piece when d <= 3), and a piece move
    could give the incumbent back: a fifth of a plateau's budget went to points already played."""
    opt = make_optimizer("auto", np.zeros(dimension), np.ones(dimension), budget=200, rng=np.random.default_rng(0))
    explored = 0
    while opt.asked < 200:
        xs = [opt.ask() for _ in range(max(1, min(opt.ready(), 200 - opt.asked)))]
        for i, arm in enumerate(opt._arms[-len(xs):]):
            if arm != 0:  # an exploring arm's point (BO's are expected improvement's business)
                explored += 1
                assert not any(np.array_equal(xs[i], p) for p in [*opt.X, *xs[:i]])
        for x in xs:
            opt.tell(x, -1.0)
    assert explored > 50


@pytest.mark.usefixtures("numerics")
@pytest.mark.parametrize("version", ["0.8", "0.9"])
def test_auto_with_earlier_options_proposes_what_that_version_proposed(version):
    """Campaigns an earlier d4sumo stored replay with its options (`EARLIER_OPTIONS`) only if its proposals
    are unchanged: a campaign of that version (`histories`: seed 11, a terraced objective, in batches), told
    back, gets every arm, design point and exploring point bit for bit, and at BO's points the same
    candidates. The default's stalls and suffix moves ask otherwise."""
    asks = check_history(f"auto {version}")
    assert sum(a["arm"] != BO for a in asks) > 15
    default = make_optimizer("auto", -np.ones(9), np.ones(9), budget=60, rng=np.random.default_rng(11))
    record = json.loads(DATA.read_text())[f"auto {version}"]
    now = tell_history(default, np.array(record["X"]), record["y"])
    assert [a["arm"] for a in now] != record["arms"]


def test_auto_a_nan_score_is_no_progress_and_holds_no_stall():
    """A first NaN is told as 0 (nothing seen to be worse than); the stall counts from real scores."""
    opt = make_optimizer("auto", LOWER, UPPER, budget=40, rng=np.random.default_rng(0), options={"stall": 3})
    for i in range(30):
        x = opt.ask()
        opt.tell(x, float("nan") if i == 0 else -100.0 + i)  # every real score a new best
        assert not opt.stalled, i


def test_auto_uniform_exploration_knows_no_stalls():
    from d4sumo.search.optimizers import resolve_options

    assert resolve_options("auto", {"version": 1})["stall"] == 0 and resolve_options("auto", {})["stall"] == 25


def test_auto_held_points_hold_pieces_at_bounds_or_one_value():
    """Held sampling: each point is at most 0.4 d pieces of equal values, a third of them at each bound."""
    opt = make_optimizer("auto", -np.ones(40), np.ones(40), budget=10, rng=np.random.default_rng(0))
    values = []
    for _ in range(300):
        z = opt._held()
        pieces = 1 + int(np.count_nonzero(np.diff(z)))
        assert 1 <= pieces <= 16
        values.extend(z[np.r_[0, np.flatnonzero(np.diff(z)) + 1]])
    at_bounds = np.mean(np.isin(values, [0.0, 1.0]))
    assert 0.55 < at_bounds < 0.78, at_bounds


def test_auto_held_points_cut_each_signal_on_its_own():
    """Throttle and brake (two signals of 20) are each cut into at most 8 pieces, none running from one
    into the other; d4sumo 0.10 (``per_signal = 0``) cut the 40 values as one run, up to 16 pieces
    wherever the cuts fell, a piece across the two."""
    def most_pieces_in_a_signal(per_signal):
        opt = make_optimizer("auto", np.zeros(40), np.ones(40), budget=10, rng=np.random.default_rng(3),
                             options={"per_signal": per_signal}, signals=(20, 20))
        draws = [opt._held() for _ in range(400)]
        return max(1 + int(np.count_nonzero(np.diff(z[a:a + 20]))) for z in draws for a in (0, 20)), draws

    most, draws = most_pieces_in_a_signal(1)
    assert most <= 8
    assert any(z[19] != z[20] and z[0] == z[19] and z[20] == z[39] for z in draws)  # one piece each, apart
    assert most_pieces_in_a_signal(0)[0] > 8


def test_auto_piece_moves_change_one_piece_or_span_of_the_incumbent():
    opt = make_optimizer("auto", LOWER, UPPER, budget=10, rng=np.random.default_rng(1), options={"suffix": 0.0})
    best = np.repeat([0.0, 0.7, 1.0, 0.2], [3, 2, 4, 1])[: opt.dimension]
    for _ in range(200):
        z = opt._piece_move(best)
        changed = np.flatnonzero(z != best)
        assert changed.size == 0 or np.all(np.diff(changed) == 1)  # one contiguous span
        if changed.size:
            assert np.all(z[changed] == z[changed[0]])  # set to one value


@pytest.mark.parametrize("signals", [(10, 10), (7, 3), (12, 1)])
def test_auto_suffix_moves_keep_the_incumbent_up_to_a_time_in_every_signal(signals):
    """A suffix move cuts every signal at one time (the same share of each one's length) and redraws only
    after it; a scalar (a signal of one value) is redrawn when the cut comes up to its middle."""
    d, longest = sum(signals), max(signals)
    opt = make_optimizer("auto", np.zeros(d), np.ones(d), budget=10, rng=np.random.default_rng(2), options={"suffix": 1.0},
                         signals=signals)
    best = np.full(d, 0.5)  # no held value is 0.5: every value redrawn changes
    cuts = set()
    for _ in range(300):
        z = opt._piece_move(best)
        cut = int(np.flatnonzero(z[:longest] != 0.5)[0])  # the longest signal comes first here
        cuts.add(cut)
        start = 0
        for n in signals:
            a = round(cut * n / longest)
            assert np.all(z[start:start + a] == 0.5) and np.all(z[start + a:start + n] != 0.5), (signals, cut)
            start += n
    assert cuts == set(range(1, longest))  # every time but the start


def test_auto_makes_no_suffix_moves_where_every_parameter_is_a_scalar():
    """A family of scalars (a sine's amplitude, period, phase) has no time to cut at: auto proposes what it
    does without suffix moves."""
    def run(options):
        opt = make_optimizer("auto", LOWER, UPPER, budget=80, rng=np.random.default_rng(5), options=options,
                             signals=(1,) * LOWER.size)
        play_in_batches(opt, lambda x: -1.0)
        return np.array(opt.X)

    assert np.array_equal(run({}), run({"suffix": 0.0}))


def test_the_layout_in_time_is_runs_that_cover_the_parameters():
    with pytest.raises(ValueError):
        make_optimizer("auto", np.zeros(4), np.ones(4), budget=10, rng=np.random.default_rng(0), signals=(2, 3))
    assert make_optimizer("bo", np.zeros(4), np.ones(4), budget=10, rng=np.random.default_rng(0)).signals == (4,)


def test_auto_falsifies_arch_comps_cc4():
    """Issue 25: ARCH-COMP's chasing cars, CC4 (tools/arch_cc.py): no uniform search of 1,500 simulations
    falsified it in 80 runs; auto's held inputs and piece moves do, in a few hundred."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
    import arch_cc

    opt = make_optimizer("auto", np.zeros(40), np.ones(40), budget=1500, rng=np.random.default_rng(3), signals=(20, 20))
    found = None
    while found is None and opt.asked < 1500:
        xs = [opt.ask() for _ in range(max(1, min(opt.ready(), 1500 - opt.asked)))]
        robustness = arch_cc.robustness("CC4", arch_cc.simulate(np.array(xs), 2))
        for x, r in zip(xs, robustness):
            opt.tell(x, -float(r))
        if (robustness < 0).any():
            found = opt.asked
    assert found is not None


def test_auto_refuses_a_share_outside_its_bounds():
    with pytest.raises(ConfigError) as info:
        make_optimizer("auto", LOWER, UPPER, budget=10, rng=np.random.default_rng(0),
                       options={"random_share": 0.9, "share_max": 0.8})
    assert info.value.field == "search.auto.random_share"


@pytest.mark.usefixtures("numerics")
def test_auto_proposes_what_bo_does_until_it_plays_an_exploring_point():
    """Its arms draw from a stream of their own: with no exploring point, auto is bo, proposal for proposal."""
    f = lambda x: -float(np.sum((x - 0.3) ** 2))  # noqa: E731
    auto = make_optimizer("auto", LOWER, UPPER, budget=100, rng=np.random.default_rng(3), options={"random_share": 0.0, "share_min": 0.0})
    bo = make_optimizer("bo", LOWER, UPPER, budget=100, rng=np.random.default_rng(3))
    for _ in range(8):
        xs, ys = [auto.ask() for _ in range(auto.ready())], [bo.ask() for _ in range(bo.ready())]
        assert np.array_equal(np.array(xs), np.array(ys))
        for a, b in zip(xs, ys):
            auto.tell(a, f(a))
            bo.tell(b, f(b))


@pytest.mark.parametrize("inducing, sparse", [(256, True), (0, False)])
def test_bo_conditions_through_inducing_points_past_that_many_scores(inducing, sparse):
    """Issue 25: at thousands of scores the exact GP cost 60-120 ms a proposal; past `inducing` scores it is
    conditioned through that many (0: exact, as campaigns stored before the option ran)."""
    opt = make_optimizer("bo", LOWER, UPPER, budget=300, rng=np.random.default_rng(0), options={"inducing": inducing})
    rng = np.random.default_rng(1)
    for _ in range(290):
        x = rng.uniform(LOWER, UPPER)
        opt.tell(x, -float(np.sum(x ** 2)))
    opt.asked = 290
    opt.ask()
    assert opt._gp.sparse == sparse and len(opt._gp.t) == 290


@pytest.mark.parametrize("name", ["bo", "auto"])
def test_edges_holds_candidates_at_the_bounds_and_none_leaves_the_proposals_as_they_were(name):
    """``edges``: a share of BO's global candidates with each coordinate, as likely as not, held at a bound (the
    pedals floored or released that win a lie); at 0, the default, no draw changes."""
    lower, upper = -np.ones(6), np.ones(6)

    def run(options):
        opt = make_optimizer(name, lower, upper, budget=40, rng=np.random.default_rng(3), options=options)
        asked = []
        while opt.asked < 40:
            xs = [opt.ask() for _ in range(min(opt.ready(), 40 - opt.asked))]
            for x in xs:
                opt.tell(x, float(np.sum(np.abs(x))))  # best at the corners
            asked += xs
        return np.array(asked[10:])  # after the design

    plain, default, held = run({}), run({"edges": 0.0}), run({"edges": 0.5})
    assert np.array_equal(plain, default)
    at_bounds = lambda xs: int(np.sum(np.isclose(np.abs(xs), 1.0, rtol=0, atol=1e-12)))  # noqa: E731
    assert at_bounds(held) > 2 * max(at_bounds(plain), 1)
    with pytest.raises(ConfigError, match=f"search.{name}.edges"):
        make_optimizer(name, lower, upper, budget=5, rng=np.random.default_rng(0), options={"edges": 1.5})


@pytest.mark.parametrize("name", ["bo", "auto"])
def test_novelty_keeps_each_proposal_apart_from_the_attacks_found_and_none_leaves_the_proposals_as_they_were(name):
    """``novelty`` = r: once an attack succeeds (a positive score), every proposal lies farther than r of the box from
    every success and every point pending, in some parameter, so the successes are distinct attacks
    (`results.analysis.distinct_count`); at 0, the default, no draw changes."""
    from d4sumo.results.analysis import distinct_count

    lower, upper = np.zeros(4), np.ones(4)

    def run(options):
        opt = make_optimizer(name, lower, upper, budget=80, rng=np.random.default_rng(5), options=options)
        asked, scores, told = [], [], []  # told: the scores told when each point was asked
        while opt.asked < 80:
            xs = []
            for _ in range(min(opt.ready(), 80 - opt.asked)):
                told.append(len(scores))
                xs.append(opt.ask())
            for x in xs:
                scores.append(0.12 - float(np.max(np.abs(x - 0.7))))  # a success within 0.12 of (0.7, .., 0.7)
                opt.tell(x, scores[-1])
                asked.append(x)
        return np.array(asked), np.array(scores), told

    plain, default = run({})[0], run({"novelty": 0.0})[0]
    assert np.array_equal(plain, default)
    (without, s0, _), (novel, s1, told) = run({"novelty": 0.0}), run({"novelty": 0.05})
    checked = 0
    for k in range(len(novel)):
        found = novel[:told[k]][s1[:told[k]] > 0.0]
        if len(found):  # its batch's earlier points, pending, too
            apart_from = np.vstack([found, novel[told[k]:k]])
            assert np.all(np.max(np.abs(apart_from - novel[k]), axis=1) > 0.05), f"proposal {k} repeats an attack"
            checked += 1
    assert checked >= 10
    distinct = [distinct_count(x[s > 0.0], lower, upper) for x, s in ((without, s0), (novel, s1))]
    assert distinct[1] == int(np.sum(s1 > 0.0)) > distinct[0], distinct  # each success an attack of its own
    with pytest.raises(ConfigError, match=f"search.{name}.novelty"):
        make_optimizer(name, lower, upper, budget=5, rng=np.random.default_rng(0), options={"novelty": 0.05, "gp_version": 1})


def test_novelty_draws_more_of_the_box_before_it_repeats_an_attack():
    """Found by review: where no candidate lay apart from the attacks found, a proposal fell back to any candidate and
    could repeat one, though points apart were left in the box. Now it draws more of the box first."""
    lower, upper = np.zeros(2), np.ones(2)
    opt = make_optimizer("bo", lower, upper, budget=40, rng=np.random.default_rng(1), options={"novelty": 0.3, "batch_size": 1})
    found = []
    for k in range(40):
        x = opt.ask()
        if found and k >= 10:  # past the initial design
            grid = np.stack(np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201)), -1).reshape(-1, 2)
            room = np.any(np.all(np.max(np.abs(grid[:, None, :] - np.array(found)[None]), axis=2) > 0.3, axis=1))
            if room:  # a point of the box lies apart: the proposal does
                assert np.all(np.max(np.abs(np.array(found) - x), axis=1) > 0.3), (x, found)
        score = 0.5 - float(np.max(np.abs(x - 0.5)))  # a success nearly everywhere
        if score > 0.0:
            found.append(x)
        opt.tell(x, score)
    assert len(found) >= 4
