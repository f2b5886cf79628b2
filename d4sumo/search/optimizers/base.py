"""The ask/tell interface every optimiser shares."""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError, check_int, check_number


class Optimizer:
    """Ask for a point in [lower, upper], tell its score (higher is better).

    ``signals`` says how the parameters lay out in time, for an optimiser that reads them as signals:
    consecutive runs of that many values, each run one signal in time order (a scalar is a run of one).
    By default all the parameters are one signal.

    Points come from the seed alone (a design, a sampler's draws: every machine draws them alike, bit for
    bit) or from a model fitted through BLAS and LAPACK, whose last bits depend on the CPU and the library
    build: an argmax over an acquisition can turn those into another point. ``modelled`` holds the
    points (0-based, in the order asked) a model proposed, or that depend on one: there another machine
    may ask otherwise (`search.runner` lets a resumed campaign's stored points stand there). Every other
    point is the seed's and the scores told's alone."""

    name = ""
    #: option -> (default, low, high); an int default means a whole number
    OPTIONS: dict[str, tuple[float, float, float]] = {}

    def __init__(self, lower: np.ndarray, upper: np.ndarray, budget: int, rng: np.random.Generator, *,
                 signals: tuple[int, ...] | None = None, **options):
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.dimension = self.lower.size
        self.signals = tuple(signals) if signals is not None else (self.dimension,)
        if sum(self.signals) != self.dimension or min(self.signals, default=1) < 1:
            raise ValueError(f"signals {self.signals}: runs of at least one value, {self.dimension} in all")
        self.budget = budget
        self.rng = rng
        self.options = self.resolve_together(check_options(self.name, self.OPTIONS, options))
        self.asked = 0
        self.modelled: set[int] = set()
        self.X: list[np.ndarray] = []
        self.y: list[float] = []

    @staticmethod
    def resolve_together(options: dict) -> dict:
        """The options, refused where each is allowed but not together (a ConfigError), and an option
        that does nothing given the others set to the value that says so (one behaviour, one definition)."""
        return options

    @property
    def outstanding(self) -> int:
        """Points asked for whose scores have not been told yet."""
        return self.asked - len(self.y)

    def ready(self) -> int:
        """How many points may be asked for now, before any outstanding score is told, such that every
        one of them is what the optimiser would ask with all earlier scores told: a batch whose episodes
        can be played side by side without changing the campaign. At least 1 when nothing is
        outstanding; by default the optimiser is sequential."""
        return 0 if self.outstanding else 1

    def ask(self) -> np.ndarray:
        if self.asked >= self.budget:
            raise ValueError(f"{self.name}: the budget of {self.budget} samples is spent")
        self.asked += 1
        return self._ask()

    def _ask(self) -> np.ndarray:
        raise NotImplementedError

    def _modelled(self) -> None:
        """The point being asked comes from a model (its last bits are this machine's)."""
        self.modelled.add(self.asked - 1)

    def tell(self, x: np.ndarray, score: float) -> None:
        score = float(score)
        if not np.isfinite(score):
            finite = [v for v in self.y if np.isfinite(v)]
            score = min(finite) if finite else 0.0
        self.X.append(np.asarray(x, dtype=float))
        self.y.append(score)

    def _unit_to_box(self, z: np.ndarray) -> np.ndarray:
        return self.lower + z * (self.upper - self.lower)

    def _box_to_unit(self, x: np.ndarray) -> np.ndarray:
        span = np.where(self.upper > self.lower, self.upper - self.lower, 1.0)
        return (np.asarray(x) - self.lower) / span


#: points a sampler whose points depend on no score proposes at a time (a batch's worth: proposing the
#: whole budget at once would only carry it around)
INDEPENDENT_BATCH = 64


def check_options(name: str, spec: dict[str, tuple[float, float, float]], options: dict | None) -> dict:
    """Every option of optimiser ``name`` (``spec``: option -> (default, low, high)), defaults filled in,
    each value checked."""
    options = dict(options or {})
    for key in options:
        if key not in spec:
            allowed = f"a key of [search.{name}]: {', '.join(spec)}" if spec else f"nothing: {name} has no options"
            raise ConfigError(f"search.{name}.{key}", options[key], allowed)
    resolved = {}
    for key, (default, low, high) in spec.items():
        value = options.get(key, default)
        field = f"search.{name}.{key}"
        resolved[key] = check_int(field, value, low, high) if isinstance(default, int) else check_number(field, value, low, high)
    return resolved
