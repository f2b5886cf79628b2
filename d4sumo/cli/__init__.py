"""Command line: parse flags, call the library, print. The CLI stays thin: flags become dotted keys
laid over the config file (`inputs`), and the library checks the one resulting document.

Every error a user can cause ends as one line `d4sumo: error: ...` and exit code 2.
"""

from __future__ import annotations

import errno
import logging
import os
import re
import signal
import sys
import threading
import traceback
from typing import Sequence

# The library (numpy, scipy, rtamt, SUMO's bindings: half a second) is imported in `main`, not here.


class Terminated(KeyboardInterrupt):
    """SIGTERM: stop as on Ctrl-C (workers stopped, nothing half-written), exit code 143."""


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


def _join_negative_lists(argv: list[str]) -> list[str]:
    """``--params -0.5,0.2,1`` as ``--params=-0.5,0.2,1``: argparse would take the list for an option."""
    from .common import LIST_OPTIONS

    out = []
    i = 0
    while i < len(argv):
        if argv[i] in LIST_OPTIONS and i + 1 < len(argv) and re.fullmatch(r"-[0-9.][0-9.eE+\-,\s]*", argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv: Sequence[str] | None = None) -> int:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _on_sigterm)
    try:  # from the first import of the library on, so a Ctrl-C while it loads is one line too
        return _run(argv)
    except KeyboardInterrupt as exc:
        if not isinstance(exc, Terminated) and not getattr(exc, "said", False):
            print("d4sumo: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130


def _run(argv: Sequence[str] | None) -> int:
    from ..errors import ConfigError, D4sumoError
    from .common import EXIT_USAGE, FLAG_KEYS
    from .parser import build_parser

    parser = build_parser()
    try:
        args = parser.parse_args(_join_negative_lists(list(sys.argv[1:] if argv is None else argv)))
    except SystemExit as exc:  # usage errors (one line, exit 2), --help, --version
        return int(exc.code or 0)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s" if args.verbose else "d4sumo: %(message)s")
    flags: dict[str, str] = {}
    for dest, key in FLAG_KEYS.items():
        if getattr(args, dest, None) is not None:
            flags[key] = "--" + dest.replace("_", "-")
    if getattr(args, "preset", None) is not None:
        flags["preset"] = "--preset"
    if getattr(args, "knots", None) is not None:
        flags.update({"attack.params": "--knots", "attack.family": "--knots"})
    elif getattr(args, "attack", None) is not None and args.command == "simulate":
        flags["attack.params"] = "--params"  # named even when it is missing
    try:
        code = args.func(args)
        sys.stdout.flush()  # inside the try: a closed pipe surfaces here, not at exit
        return code
    except ConfigError as exc:
        flag = flags.get(exc.field) or flags.get(exc.field.split(":")[0])
        field = f"{flag} ({exc.field})" if flag and not exc.field.startswith("--") else exc.field
        print(f"d4sumo: error: {field}: got {exc.given!r}; allowed: {exc.allowed}", file=sys.stderr)
        return EXIT_USAGE
    except D4sumoError as exc:
        hint = ""
        if exc.__cause__ is not None:  # an error of a user's controller, in its own code: -v shows where
            if args.verbose:
                traceback.print_exception(exc.__cause__)
            else:
                hint = " (d4sumo -v shows its traceback)"
        print(f"d4sumo: error: {exc}{hint}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        # the reader went away (`d4sumo export db | head`): stop quietly, as command-line tools do
        _drop_stdout()
        return 141
    except OSError as exc:
        # standard output that cannot take what is printed (`> /dev/full`, a full disk); the files a
        # command writes are checked by the command, and name themselves (exc.filename)
        if exc.filename is not None or exc.errno not in (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EFBIG):
            raise
        _drop_stdout()
        print(f"d4sumo: error: standard output could not be written ({exc.strerror})", file=sys.stderr)
        return EXIT_USAGE


def _drop_stdout() -> None:
    """What is left in stdout's buffer goes nowhere: Python's own flush at exit would fail again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
