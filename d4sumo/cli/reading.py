"""The commands that read results: export, report, plot. None of them imports a user's controller to
read a database; report and plot replay samples through SUMO, which does."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from ..errors import ConfigError, D4sumoError
from ..files import part_of, remove_stale_parts
from .common import check_distinct, check_output_file


def cmd_export(args: argparse.Namespace) -> int:
    from ..results.export import write_csv
    from ..search.campaign import open_store

    if args.openscenario is not None or args.sample is not None:
        return _export_openscenario(args)

    with open_store(args.db, create=False) as store:
        known = [c.id for c in store.campaigns()]
        if args.campaign is not None and args.campaign not in known:
            raise ConfigError("--campaign", args.campaign, f"a campaign id of {args.db}: {', '.join(map(str, known)) or 'none'}")
        out_path = check_output_file("--out", args.out)
        if out_path is None:
            write_csv(store, sys.stdout, args.campaign)
            return 0
        remove_stale_parts(out_path)
        tmp = part_of(out_path)
        try:
            with open(tmp, "w", newline="") as out:
                rows = write_csv(store, out, args.campaign)
            os.replace(tmp, out_path)  # whole or not at all
        except OSError as exc:
            raise D4sumoError(f"--out: {out_path} could not be written ({exc.strerror}); nothing was written") from None
        finally:
            tmp.unlink(missing_ok=True)
    print(f"{rows} samples written to {args.out}", file=sys.stderr)
    return 0


def _export_openscenario(args: argparse.Namespace) -> int:
    from ..results.openscenario import export_openscenario
    from ..results.records import load_records

    if args.sample is None:
        raise ConfigError("sample", "none given", "the id of the sample to write as OpenSCENARIO (d4sumo export DB SAMPLE --openscenario DIR)")
    if args.openscenario is None:
        raise ConfigError("--openscenario", "none given", "a folder to write the sample's road.xodr and scenario.xosc into "
                                                  "(a sample alone is exported as OpenSCENARIO)")
    if args.out is not None or args.campaign is not None:
        raise ConfigError("--out" if args.out is not None else "--campaign", str(args.out or args.campaign),
                          "no CSV flag beside --openscenario")
    out = args.openscenario
    if out.exists() and not out.is_dir():
        raise ConfigError("--openscenario", str(out), "a folder (this is a file)")
    if not (out if out.exists() else out.parent if str(out.parent) else Path(".")).is_dir():
        raise ConfigError("--openscenario", str(out), "a folder, or a new one in an existing folder")
    records = {r.sample_id: r for r in load_records([args.db])}
    if args.sample not in records:
        raise ConfigError("sample", args.sample, f"a sample id of {args.db} (1 .. {max(records, default=0)})")
    road, scenario = export_openscenario(records[args.sample], out)
    print(f"sample {args.sample}: {road} (OpenDRIVE, netconvert's) and {scenario} (OpenSCENARIO 1.2)")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..results.report import build_report
    from ..search.campaign import open_store

    if args.out.exists() and not args.out.is_dir():
        raise ConfigError("--out", str(args.out), "a folder for index.html and its figures (this is a file)")
    check_distinct(args.db)
    if not args.out.parent.is_dir():
        raise ConfigError("--out", str(args.out), f"a folder in an existing folder ({args.out.parent} does not exist)")
    if not 0 <= args.severe <= 100:
        raise ConfigError("--severe", args.severe, "a whole number in [0, 100]")
    for db in args.db:  # every database readable and sound before any output
        with open_store(db, create=False) as store:
            store.campaigns()
            for _ in store.iter_samples():
                pass
    try:  # a folder that can be made here (/proc's parent exists, yet nothing can be made in it), tried away
        with tempfile.TemporaryDirectory(dir=args.out.parent):
            pass
    except OSError as exc:
        raise ConfigError("--out", str(args.out), f"a folder that can be created and written ({exc.strerror})") from None
    if args.out.is_dir() and not os.access(args.out, os.W_OK):
        raise ConfigError("--out", str(args.out), "a folder you may write (permission denied)")
    steps = ["tables", "heatmaps", "time-space diagrams", "clusters"]
    with tqdm(total=len(steps), desc="report", disable=args.quiet, file=sys.stderr) as bar:
        current: list[str] = []

        def progress(what: str) -> None:  # "tables: ..." goes on with the step "tables"
            step = what.partition(":")[0]
            if current and step != current[-1]:
                bar.update(1)
            current.append(step)
            bar.set_postfix_str(what)

        index = build_report(args.db, args.out, severe=args.severe, progress=progress)
        bar.update(bar.total - bar.n)
    print(f"report written to {index}")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from ..results.report import plot_figure

    check_distinct(args.db)
    print(plot_figure(args.db, args.kind, args.out, sample=args.sample, fcd_path=check_output_file("--fcd", args.fcd),
                      attack=args.attack, optimizer=args.optimizer, start=args.start, setpoint_m=args.setpoint,
                      speed_mps=args.speed, keys=args.keys))
    return 0
