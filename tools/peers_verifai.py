"""VerifAI's samplers over a pipe, for tools/bench_peers.py: run by the Python of an environment that has VerifAI
(its metric-temporal-logic pins attrs < 23, which PSY-TaLiRo and d4sumo's own environment do not hold), it needs
nothing of d4sumo.

It samples the unit cube of the given dimension with one of VerifAI's samplers, as a user of VerifAI would drive
it: for each sample, it writes the point as one JSON line to stdout, reads the robustness of the episode d4sumo
played there from stdin (one number a line; positive: the attack succeeded), and feeds VerifAI its negation
(VerifAI's samplers look for low values: a property falsified).

Usage: PYTHON tools/peers_verifai.py SAMPLER DIMENSION SAMPLES SEED   (SAMPLER: bo, ce, halton or random)
"""

from __future__ import annotations

import json
import random
import sys

import numpy as np
from dotmap import DotMap
from verifai.features import Box, Feature, FeatureSpace
from verifai.samplers import FeatureSampler


def sampler(name: str, dimension: int):
    space = FeatureSpace({"x": Feature(Box(*[(0.0, 1.0)] * dimension))})
    if name == "bo":
        return FeatureSampler.bayesianOptimizationSamplerFor(space, DotMap(init_num=5))  # VerifAI's default
    if name == "ce":
        return FeatureSampler.crossEntropySamplerFor(space)
    if name == "halton":
        return FeatureSampler.haltonSamplerFor(space)
    if name == "random":
        return FeatureSampler.randomSamplerFor(space)
    raise SystemExit(f"peers_verifai.py: got sampler {name!r}; allowed: bo, ce, halton, random")


def main() -> None:
    name, dimension, samples, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    random.seed(seed)  # VerifAI draws from both
    np.random.seed(seed)
    s = sampler(name, dimension)
    feedback = None
    for _ in range(samples):
        point = s.nextSample(feedback)
        print(json.dumps([float(v) for v in point.x]), flush=True)
        line = sys.stdin.readline()
        if not line:
            return
        feedback = -float(line)


if __name__ == "__main__":
    main()
