"""What the scripts in tools/ share on their command lines, as d4sumo's own: a usage error or a refused
value is one line and exit 2 (`Parser`, `run_main`), Ctrl-C exits 130 and SIGTERM 143 by the same way
out (worker pools stopped in ``finally``); optimiser specs (``name`` or ``name:key=value,...``) are checked
before any run."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from typing import Callable

from d4sumo.errors import ConfigError, D4sumoError, refusal
from d4sumo.search.optimizers import resolve_options

SPEC_FORM = "an optimiser's name, or name:key=value,key=value with its options (numbers)"


class Parser(argparse.ArgumentParser):
    """argparse with the script's docstring as its help, and a usage error in one line, not the whole usage."""

    def __init__(self, description: str | None, **kwargs):
        super().__init__(description=description, formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")

    def check_counts(self, bounds: dict[str, tuple]) -> None:
        """``{flag: (value, least)}`` or ``(value, least, most)`` for whole-number flags: a value out of its
        bounds is refused (None: not given)."""
        for flag, (value, low, *high) in bounds.items():
            if value is not None and (value < low or (high and value > high[0])):
                self.error(refusal(flag, value, f"a whole number in [{low}, {high[0]}]" if high else
                                   f"a whole number of at least {low}"))

    def check_optimizers(self, specs: list[str]) -> None:
        """Every optimiser spec names an optimiser and options it takes, each within its range."""
        for spec in specs:
            try:
                resolve_options(*optimizer_of(spec))
            except ConfigError as e:
                self.error(f"--optimizers: {spec!r}: {e}")
            except ValueError:
                self.error(refusal("--optimizers", spec, SPEC_FORM))


def run_main(main: Callable[[], int | None]) -> None:
    """A script's ``main``, its return value the exit code (None: 0): d4sumo's refusals in one line with
    exit 2, Ctrl-C 130, SIGTERM 143."""
    def terminate(*_):
        raise SystemExit(143)  # unwinds like Ctrl-C: worker pools are stopped on the way out

    signal.signal(signal.SIGTERM, terminate)
    script = Path(sys.argv[0]).name
    try:
        code = main()
    except D4sumoError as e:
        print(f"{script}: error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print(f"{script}: interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(code)


def optimizer_of(spec: str) -> tuple[str, dict]:
    """``name`` or ``name:key=value,key=value``: an optimiser and its options."""
    name, _, options = spec.partition(":")
    return name, {k: int(v) if v.lstrip("-").isdigit() else float(v) for k, v in (o.split("=") for o in options.split(",") if o)}
