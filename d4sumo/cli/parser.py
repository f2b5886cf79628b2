"""The command line's flags: one parser, a subcommand per command."""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import __version__
from ..model.attacks.pedals import FAMILIES
from ..model.stepping.batch import DEFAULT_BATCH
from ..model.config import MANEUVERS, START_MODES
from ..search.optimizers import OPTIMIZERS
from .campaigns import cmd_falsify, cmd_sweep
from .common import EXIT_USAGE
from .episodes import cmd_build_fmu, cmd_replay, cmd_scenarios, cmd_simulate
from .reading import cmd_export, cmd_plot, cmd_report


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and exit 2), not the whole usage."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"d4sumo: error: {message} (see `{self.prog} --help`)\n")


def _add_episode_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario (flags override the config file)")
    g.add_argument("--config", type=Path, help="TOML config file ([scenario], [vehicle], [controller], [attack], [spec], [search])")
    g.add_argument("--preset", help="a bundle of options under the file and the flags: paper-as-run (the paper as its "
                                    "authors' code ran it, with --attack persistent, intermittent or knots)")
    g.add_argument("--network", help="the road: a shipped variant (see `d4sumo scenarios`), a folder of one *.nod.xml and "
                                     "one *.edg.xml (or of one *.net.xml), or a *.net.xml file (or .net.xml.gz: netconvert's, netgenerate's; "
                                     "an OSM file: netconvert --osm-files map.osm -o map.net.xml first) [highway_4lane]")
    g.add_argument("--followers", type=int, help="followers behind the attacker, 1..10 [3]")
    g.add_argument("--setpoint", type=float, help="bumper-to-bumper setpoint distance d in m [7]")
    g.add_argument("--speed", type=float, help="target speed in m/s [25]")
    g.add_argument("--start", choices=START_MODES,
                   help="rest: all at 0 m/s; steady: all at the target speed; warmup: drive from rest for --warmup s, "
                        "attack after [rest]")
    g.add_argument("--maneuver", choices=MANEUVERS,
                   help="inlane: the attacker leads the platoon in its lane (the paper); cutin: it changes into the "
                        "platoon's lane in front of a follower; cutout: it leads, then leaves the lane to reveal a "
                        "slower car (multi-lane roads; the optimiser picks the lane change time t_lc_s); swerve: it "
                        "leads, its lane at scenario.swerve_knots times searched with its pedals [inlane]")
    g.add_argument("--warmup", type=float, help="seconds driven from rest before the attack with --start warmup [15]")
    g.add_argument("--step", type=float, help="simulation step in s [0.05]")
    g.add_argument("--duration", type=float, help="seconds from the attack's start to the episode's end [60]")
    g.add_argument("--length", type=float, help="vehicle length in m [4.5]")
    g.add_argument("--controller",
                   help="follower controller: switching, timegap, idm, the cooperative cacc, ploeg or consensus (they read V2V "
                        "beacons), a SUMO car-following model as sumo:MODEL (sumo:ACC, sumo:CACC, sumo:IDM, sumo:CC, ...), an FMU "
                        "as fmu:PATH or package.module:ClassName; a comma-separated list gives one per follower, v1 first [switching]")
    g.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="TABLE.KEY=VALUE",
        help="any value of the config file, e.g. --set controller.acc_kp=1.2, --set controller.tau=1.2 (sumo:MODEL), "
             "--set controller.v2.tau=1.2 (one follower of a mixed platoon) or --set search.ce.batch_size=20 (repeatable)",
    )


def _add_spec_options(g) -> None:
    g.add_argument("--formula", help="an STL formula (rtamt syntax) over the trace's signals instead of the paper's psi")
    g.add_argument("--d-safe", type=float, dest="d_safe", help="d_safe of the paper's psi in m [0]")


def _add_knot_options(g) -> None:
    g.add_argument("--delta", type=float, help="knot spacing Delta in s [6]")
    g.add_argument("--horizon", type=float, help="last knot time in s [48; with --knots, the knots' span]")


def _add_batch_option(p) -> None:
    p.add_argument("--batch", type=int, default=DEFAULT_BATCH, metavar="N",
                   help=f"play up to N episodes an optimiser proposes together side by side in one SUMO (1: one at a "
                        f"time; the results are the same, bit for bit) [{DEFAULT_BATCH}]")


class _Version(argparse.Action):
    """--version: the version, and which optional speed-ups this install has (looked up only when asked)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kwargs):
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0,
                         help="show the version and the speed-ups this install has, and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from ..engine.calls import fast_paths

        print(f"d4sumo {__version__}\n{fast_paths()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The command line: one subcommand each, its options in its own function below."""
    parser = Parser(prog="d4sumo", description="Adversarial driving maneuvers against ACC platoons, on SUMO.")
    parser.add_argument("--version", action=_Version)
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    _add_scenarios(sub)
    _add_simulate(sub)
    _add_falsify(sub)
    _add_sweep(sub)
    _add_report(sub)
    _add_plot(sub)
    _add_replay(sub)
    _add_export(sub)
    _add_build_fmu(sub)
    return parser


def _add_scenarios(sub) -> None:
    p = sub.add_parser("scenarios", help="list the network variants shipped with d4sumo")
    p.set_defaults(func=cmd_scenarios)


def _add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="play one episode and summarise it")
    _add_episode_options(p)
    g = p.add_argument_group("attack (with none, the attacker cruises at the target speed)")
    g.add_argument("--knots", help="knot values in [-1, 1], comma-separated, joined by PCHIP (one every --delta s); "
                        "with a cut-in or cut-out, then the lane change time t_lc_s; with a swerve, then its lanes "
                        "lane_1 .. lane_K (each in [0, swerve_lanes], its whole part the lane)")
    g.add_argument("--constant", type=float, help="a constant attacker command in [-1, 1] from the attack's start")
    g.add_argument("--attack", choices=FAMILIES, help="attack family (with --params)")
    g.add_argument("--params", help="comma-separated parameter values of the family, e.g. --attack sine --params 0.5,0.2,0")
    _add_knot_options(g)
    g = p.add_argument_group("specification and output")
    _add_spec_options(g)
    g.add_argument("--fcd", type=Path, help="write SUMO's FCD output (with accelerations) to this file")
    g.add_argument("--json", action="store_true", help="print a machine-readable summary")
    g.add_argument("--gui", action="store_true", help="watch the episode in sumo-gui (needs a display)")
    p.set_defaults(func=cmd_simulate)


def _add_falsify(sub) -> None:
    p = sub.add_parser("falsify", help="run a campaign: search for attacks that make the followers crash")
    _add_episode_options(p)
    g = p.add_argument_group("search")
    g.add_argument("--attack", choices=[f for f in FAMILIES if f != "constant"], help="attack family [knots]")
    _add_knot_options(g)
    g.add_argument("--optimizer", choices=OPTIMIZERS,
                   help="auto (BO, exploring held inputs until a first attack), bo (the paper's), turbo (trust-region BO, for many parameters), ce, ce-bucket (the paper's VerifAI sampler), cmaes, random or halton [auto]")
    g.add_argument("--samples", type=int, help="budget: episodes to simulate [100]")
    g.add_argument("--seed", type=int, help="seed: the same seed repeats the campaign exactly [0]")
    _add_spec_options(g)
    _add_batch_option(g)
    p.add_argument("--db", type=Path, default=Path("results.sqlite"), help="results database (created if new) [results.sqlite]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print a machine-readable summary")
    p.set_defaults(func=cmd_falsify)


def _add_sweep(sub) -> None:
    p = sub.add_parser("sweep", help="run a grid of campaigns (local processes or a Dask cluster); resumable")
    p.add_argument("sweep", type=Path, help="sweep file (TOML: [grid] of lists, [search] samples, fixed tables)")
    p.add_argument("--db", type=Path, default=Path("results.sqlite"), help="results database [results.sqlite]")
    p.add_argument("--workers", type=int, help="local worker processes [the cores this process may run on]")
    p.add_argument("--dask", metavar="ADDRESS",
                   help="run on a Dask scheduler (e.g. tcp://10.0.0.5:8786), or 'local' for a local Dask cluster of --workers")
    p.add_argument("--dask-timeout", type=float, default=30.0, metavar="S", help="seconds to wait for the scheduler [30]")
    p.add_argument("--dask-proposals", choices=["client", "workers"], default=None,
                   help="where a Dask sweep's optimisers run: on this client, so that every campaign's samples are "
                        "the ones it gives alone here whatever machines the workers are, or spread over the workers, "
                        "each proposing with its own numerics [client]")
    p.add_argument("--part", metavar="K/N",
                   help="run part K of N of the grid (every N-th campaign from the K-th), for N clients that share a "
                        "sweep, each with its own --db; `d4sumo report` reads their databases together")
    _add_batch_option(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)


def _add_report(sub) -> None:
    p = sub.add_parser("report", help="HTML report: the paper's tables, heatmaps, time-space diagrams, clusters")
    p.add_argument("db", type=Path, nargs="+", help="results database(s)")
    p.add_argument("--out", type=Path, default=Path("report"), help="folder for index.html and figures [report]")
    p.add_argument("--severe", type=int, default=3, help="time-space diagrams of the N most severe attacks [3]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_report)


def _add_plot(sub) -> None:
    p = sub.add_parser("plot", help="draw one figure: time-space, accel, heatmap, clusters or map (where the system fails)")
    p.add_argument("kind", choices=("time-space", "accel", "heatmap", "clusters", "map"))
    p.add_argument("db", type=Path, nargs="+", help="results database(s)")
    p.add_argument("--out", type=Path, required=True, help="image file (.png, .pdf, .svg)")
    p.add_argument("--sample", type=int, help="sample id (time-space, accel)")
    p.add_argument("--fcd", type=Path, help="also keep the replay's FCD in this file (time-space, accel)")
    p.add_argument("--attack", help="only this attack family (heatmap, clusters)")
    p.add_argument("--optimizer", help="only this optimiser")
    p.add_argument("--start", choices=START_MODES, help="only this start mode")
    p.add_argument("--setpoint", type=float, help="only this setpoint in m")
    p.add_argument("--speed", type=float, help="only this target speed in m/s")
    p.add_argument("--keys", help="map: the one or two searched keys it is drawn over, comma-separated (setpoint_m,v2v.loss) "
                                  "[the first two the campaigns searched]")
    p.set_defaults(func=cmd_plot)


def _add_replay(sub) -> None:
    p = sub.add_parser("replay", help="re-simulate one stored sample and check that it reproduces (exit 1 if not; FCD, sumo-gui)")
    p.add_argument("db", type=Path, help="results database")
    p.add_argument("sample", type=int, help="sample id (as printed by falsify and export)")
    p.add_argument("--fcd", type=Path, help="write SUMO's FCD output to this file")
    p.add_argument("--gui", action="store_true", help="watch it in sumo-gui (needs a display)")
    p.add_argument("--json", action="store_true", help="print a machine-readable summary")
    p.add_argument("--openscenario", type=Path, metavar="XOSC",
                   help="play the attacker's motion from a scenario.xosc `export --openscenario` wrote, and check that "
                        "the same crash comes (pair, and time within a step)")
    p.add_argument("--network", type=Path, help="with --openscenario: on this road instead (a network file, or the "
                                                "exported road.xodr, which netconvert imports)")
    p.set_defaults(func=cmd_replay)


def _add_export(sub) -> None:
    p = sub.add_parser("export", help="write stored samples to CSV, or one as OpenSCENARIO and OpenDRIVE")
    p.add_argument("db", type=Path, help="results database")
    p.add_argument("sample", type=int, nargs="?", help="a sample id (with --openscenario)")
    p.add_argument("--out", type=Path, help="CSV file [standard output]")
    p.add_argument("--campaign", type=int, help="only this campaign id")
    p.add_argument("--openscenario", type=Path, metavar="DIR",
                   help="write the sample's road (DIR/road.xodr) and episode (DIR/scenario.xosc, OpenSCENARIO 1.2)")
    p.set_defaults(func=cmd_export)


def _add_build_fmu(sub) -> None:
    p = sub.add_parser("build-fmu", help="build the paper's switching controller as an FMU for this machine (CMake, a C compiler)")
    p.add_argument("--fmi", type=int, default=2, help="FMI version: 2 or 3 [2]")
    p.add_argument("--out", type=Path, default=Path("switching.fmu"), help="the FMU file to write [switching.fmu]")
    p.set_defaults(func=cmd_build_fmu)
