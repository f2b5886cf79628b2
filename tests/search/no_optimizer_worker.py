"""A Dask worker's preload: any optimiser asked for a point in that worker fails. With the optimisers on the
client, a sweep never asks one there."""

from __future__ import annotations


def dask_setup(worker) -> None:
    from d4sumo.search.optimizers.base import Optimizer

    def ask(self):
        raise RuntimeError("an optimiser was asked for a point on a worker")

    Optimizer.ask = ask
