"""Stored histories (points and scores, as a campaign stores them) told back to an optimiser, as a campaign
resumed from a database tells them: what a proposal must be, checked on what is the same on every machine.

A model's proposal is an argmax of expected improvement over candidates. The candidates come from the
seed and the stored history alone, so every machine draws them alike. The GP passes through BLAS and
LAPACK, whose last bits depend on the CPU, and its hyperparameters' learning (L-BFGS-B) amplifies them:
on this kind of machine, with OpenBLAS pinned to other kernels, the expected improvements of one
history's candidates differed by up to 2%, and at some points the stored proposal's expected improvement
was nothing beside the best (relative deficits up to 100% with the Prescott, Nehalem, Core2 and Atom
kernels, none with Haswell and Zen): no tolerance on it holds across machines. So a stored model
proposal is checked to be one of this machine's candidates; every other point (a design point, an
exploring arm's) must be the one asked, bit for bit, and so must the arm of every point. The GP itself
is checked against scikit-learn's on one machine (`test_gp.py`).

Recorded by ``python tests/search/histories.py`` into ``data/histories.json`` (only when a change is meant
to change proposals).
"""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from d4sumo.search.optimizers import gp, make_optimizer
from d4sumo.search.optimizers.bayes import BayesianOptimization

DATA = Path(__file__).parent / "data" / "histories.json"


def terraced(x) -> float:
    """A plateau of terraces (scores to one decimal), where auto's exploring arms matter."""
    return -round(float(np.sum((np.asarray(x) - 0.2) ** 2)), 1)


def bumpy(x) -> float:
    return -float(np.sum((np.asarray(x) - 0.2) ** 2)) + 0.3 * float(np.sin(5 * x[0]))


#: name -> (optimiser, options, seed, budget, objective), as each earlier version ran (`EARLIER_OPTIONS`)
HISTORIES = {
    "auto 0.8": ("auto", {"stall": 0, "suffix": 0.0, "patience": 0}, 11, 60, terraced),
    "auto 0.9": ("auto", {"suffix": 0.0, "patience": 0}, 11, 60, terraced),
    "bo 0.2": ("bo", {"batch_size": 1, "gp_version": 1}, 3, 25, bumpy),
}


def nudge_numerics(monkeypatch) -> None:
    """Every score the GP models nudged by one ulp: the last bits another CPU's BLAS kernel changes."""
    fit, skopt_fit = gp.GaussianProcess.fit, BayesianOptimization._fit
    monkeypatch.setattr(gp.GaussianProcess, "fit", lambda self, Z, y, learn: fit(self, Z, np.nextafter(y, np.inf), learn))
    monkeypatch.setattr(BayesianOptimization, "_fit",
                        lambda self, Z, s, relearn: skopt_fit(self, Z, np.nextafter(s, np.inf), relearn))


@pytest.fixture(params=["as computed", "one ulp off"])
def numerics(request, monkeypatch) -> str:
    """Run a test twice: with the GP's numerics as this machine computes them, and one ulp off. A test that
    passes both ways asserts what holds on any machine, not this one's last bits."""
    if request.param == "one ulp off":
        nudge_numerics(monkeypatch)
    return request.param


def optimizer(name: str):
    kind, options, seed, budget, _ = HISTORIES[name]
    return make_optimizer(kind, -np.ones(9), np.ones(9), budget=budget, rng=np.random.default_rng(seed), options=options)


@contextmanager
def acquisitions(opt):
    """Each model proposal's candidates (in the box) and expected improvements, in the order asked."""
    seen: list[tuple[np.ndarray, np.ndarray]] = []
    real_gp, real_skopt = gp.GaussianProcess.expected_improvement, None

    def spy(self, C, best, xi):
        ei = real_gp(self, C, best, xi)
        seen.append((opt._unit_to_box(C), ei))
        return ei

    import skopt.acquisition

    real_skopt = skopt.acquisition.gaussian_ei

    def spy_skopt(C, model, **kwargs):
        ei = real_skopt(C, model, **kwargs)
        seen.append((opt._unit_to_box(C), ei))
        return ei

    gp.GaussianProcess.expected_improvement = spy
    skopt.acquisition.gaussian_ei = spy_skopt
    try:
        yield seen
    finally:
        gp.GaussianProcess.expected_improvement = real_gp
        skopt.acquisition.gaussian_ei = real_skopt


def tell_history(opt, X, y) -> list[dict]:
    """Ask as a campaign does (a batch of ``ready()`` points, then their scores), telling the stored points
    and scores in place of the asked ones. For each point: what was asked, whether a model proposed it,
    its arm (auto) and, for a model's, the candidates and their expected improvements."""
    asks: list[dict] = []
    with acquisitions(opt) as seen:
        while opt.asked < len(X):
            batch = []
            for _ in range(max(1, min(opt.ready(), len(X) - opt.asked))):
                before = len(seen)
                x = opt.ask()
                modelled = len(seen) > before
                batch.append({"x": x, "modelled": modelled, "acquisition": seen[-1] if modelled else None,
                              "arm": opt._arms[-1] if hasattr(opt, "_arms") else None})
            for a in batch:
                i = len(opt.y)
                opt.tell(np.asarray(X[i]), y[i])
            asks += batch
    return asks


def check_history(name: str, opt=None) -> list[dict]:
    """Tell the recorded history of ``name`` back; assert every point is what this machine must ask there.
    Returns the asks."""
    record = json.loads(DATA.read_text())[name]
    X, y = np.array(record["X"]), record["y"]
    asks = tell_history(opt or optimizer(name), X, y)
    if record["arms"] is not None:
        assert [a["arm"] for a in asks] == record["arms"]
    for i, (a, stored) in enumerate(zip(asks, X)):
        if not a["modelled"]:  # the seed's and the arms' points: every machine's, bit for bit
            assert np.array_equal(a["x"], stored), i
            continue
        candidates, _ = a["acquisition"]
        assert np.any(np.all(np.abs(candidates - stored) <= 1e-12, axis=1)), f"stored point {i}: not one of the candidates"
    return asks


def record() -> None:
    """Play each history with its own objective on this machine and store it."""
    out = {}
    for name, (_, _, _, budget, f) in HISTORIES.items():
        opt = optimizer(name)
        arms = []
        while opt.asked < budget:
            xs = [opt.ask() for _ in range(max(1, min(opt.ready(), budget - opt.asked)))]
            if hasattr(opt, "_arms"):
                arms += opt._arms[-len(xs):]
            for x in xs:
                opt.tell(x, f(x))
        out[name] = {"X": [list(map(float, x)) for x in opt.X], "y": list(map(float, opt.y)),
                     "arms": [int(a) for a in arms] if hasattr(opt, "_arms") else None}
    DATA.parent.mkdir(exist_ok=True)
    DATA.write_text(json.dumps(out, indent=0) + "\n")


if __name__ == "__main__":
    record()
