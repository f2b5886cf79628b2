"""What the scripts in tools/ share on their command lines: a usage error is one line and exit 2 (as
d4sumo's own), and optimiser specs (``name`` or ``name:key=value,...``) are checked before any run."""

from __future__ import annotations

import argparse

import numpy as np

from d4sumo.errors import ConfigError
from d4sumo.search.optimizers import make_optimizer

SPEC_FORM = "an optimiser's name, or name:key=value,key=value with its options (numbers)"


class Parser(argparse.ArgumentParser):
    """argparse with the script's docstring as its help, and a usage error in one line, not the whole usage."""

    def __init__(self, description: str | None, **kwargs):
        super().__init__(description=description, formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")

    def check_at_least(self, **least: tuple[int | float | None, int | float]) -> None:
        """``flag=(value, least)`` for each flag: a value under its least is refused (None: not given)."""
        for flag, (value, low) in least.items():
            if value is not None and value < low:
                self.error(f"--{flag.replace('_', '-')}: got {value}; allowed: a number of at least {low}")

    def check_optimizers(self, specs: list[str]) -> None:
        """Every optimiser spec names an optimiser and options it takes, each within its range."""
        for spec in specs:
            try:
                name, options = optimizer_of(spec)
                make_optimizer(name, np.zeros(1), np.ones(1), budget=1, rng=np.random.default_rng(0), options=options)
            except ConfigError as e:
                self.error(f"--optimizers: {spec!r}: {e}")
            except ValueError:
                self.error(f"--optimizers: got {spec!r}; allowed: {SPEC_FORM}")


def optimizer_of(spec: str) -> tuple[str, dict]:
    """``name`` or ``name:key=value,key=value``: an optimiser and its options."""
    name, _, options = spec.partition(":")
    return name, {k: int(v) if v.lstrip("-").isdigit() else float(v) for k, v in (o.split("=") for o in options.split(",") if o)}
