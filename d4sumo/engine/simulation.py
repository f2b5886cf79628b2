"""Playing episodes in SUMO: the checks an episode must pass before it runs, and the entry points that
play one episode (`simulate`) or many side by side in one SUMO (`simulate_batch`). The step loop is
`engine.loop.play`; everything that talks to SUMO is in `engine.sumo`.

A collision is any bumper overlap at the end of a step, measured on SUMO's positions along the route
(`platoon.collisions_at`): SUMO's own reports miss overlaps of 1 mm or less; among traffic, inside a
junction, any overlap of two bodies in 2D (`junctions`). The episode ends at the
first one: SUMO lets the cars drive through each other afterwards, so later data are not physical.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from ..errors import ConfigError, SumoError
from ..files import part_of, remove_stale_parts
from ..model.stepping.batch import episode_configs
from ..model.config import EpisodeConfig
from ..model.attacks.maneuvers import REAR_START_M, AttackPlan, check_road_lanes, maneuver_of
from ..model.stepping.platoon import followers_of, longest_duration_s, road_needed_m
from ..model.stepping.trace import Episode
from .loop import DETACH_AT, play
from .scenarios import MAX_COPIES, Road, batch_road, config_road
from .command import check_additional, check_options, followers_file, sumo_command, traffic_files
from .sumo import load_platoon, open_world
from .warmup import traffic_state

log = logging.getLogger(__name__)

__all__ = ["check_road", "check_episode", "drives_one_lane", "simulate", "simulate_batch", "shares_sumo", "sumo_command", "load_platoon",
           "DETACH_AT"]

def check_road(config: EpisodeConfig, road: Road) -> None:
    """Refuse episodes the road cannot hold: a target speed above the limit, or a road too short."""
    check_road_lanes(config, road.name, road.lanes)
    if config.maneuver_class.lateral and not road.even_lanes:  # who follows whom across lanes compares positions
        raise ConfigError("scenario.maneuver", config.maneuver,
                          f"a road whose lanes are as long as each other ({road.name}'s are not, on a curve or at a junction), "
                          "or maneuver inlane")
    if config.maneuver_class.lateral and len(road.lane_widths_m) > 1:  # which lanes a car is in reads one width
        raise ConfigError("scenario.maneuver", config.maneuver,
                          f"a road whose lanes are of one width ({road.name}'s are "
                          f"{' to '.join(f'{w:g}' for w in (road.lane_widths_m[0], road.lane_widths_m[-1]))} m wide), "
                          "or maneuver inlane")
    own = dict(config.vehicles)
    for vid, v in zip(config.vehicle_ids, config.car_vehicles):
        for lane in range(config.maneuver_class.lanes_for(config)):
            edge = road.closed(lane, v.vclass)
            if edge is not None:
                raise ConfigError(f"vehicle.{vid}.vclass" if "vclass" in dict(own.get(vid, ())) else "vehicle.vclass", v.vclass,
                                  f"a class {road.name} lets drive in lane {lane} (edge {edge} closes it to {v.vclass})")
    if config.speed_mps > road.speed_limit_mps + 1e-9:
        raise ConfigError("scenario.speed_mps", config.speed_mps, f"at most the speed limit of {road.name}: {road.speed_limit_mps:g} m/s")
    start = max(car.position_m for car in maneuver_of(config).cars())
    if start > road.first_edge_m and config.join_m != REAR_START_M:  # placed by the user: off the route
        raise ConfigError("scenario.join_m", config.join_m, f"a place on the route's first edge {road.route_edges[0]} "
                                                            f"({road.first_edge_m:g} m) the whole platoon fits behind (at most "
                                                            f"{config.join_m - (start - road.first_edge_m):.1f} m)")
    if start > road.first_edge_m:
        raise ConfigError(
            "scenario.network",
            road.name,
            f"a road whose first edge holds the platoon's start ({start:.1f} m; the first edge is {road.first_edge_m:g} m)",
        )
    needed = road_needed_m(config, road.speed_limit_mps)
    if needed > road.length_m:
        longest = longest_duration_s(config, road.length_m, road.speed_limit_mps)
        accel = max(v.max_accel_mps2 for v in config.car_vehicles)
        fits = (f"at most {longest:g} s fits, the frontmost car accelerating at most at {accel:g} m/s^2 up to the "
                f"{road.speed_limit_mps:g} m/s limit" + (f" after the {config.attack_start_s:g} s warm-up" if config.attack_start_s else "")
                if longest > 0 else "none fits: use a longer road")
        raise ConfigError(
            "scenario.duration_s",
            config.duration_s,
            f"an episode that fits on {road.name} ({road.length_m:g} m; this one may need {needed:.0f} m; {fits})",
        )


def check_episode(config: EpisodeConfig, road: Road) -> Path | None:
    """Everything an episode needs checked before it runs: the road, and SUMO's models' parameters.
    Returns the followers' checked vehicle-type file (None when no follower is SUMO-driven)."""
    if road.given != config.network_given:  # a caller's mistake, never a user's: the episode would be another one
        raise ValueError(f"a road {'run as given' if road.given else 'rebuilt'} for a configuration whose network is "
                         f"{'run as given' if config.network_given else 'rebuilt'} (`scenarios.config_road` builds its own)")
    check_road(config, road)
    check_options(config, road)  # SUMO options it refuses
    check_additional(config, road)  # and additional files
    traffic_files(config, road)  # a demand SUMO refuses is refused before any episode runs
    return followers_file(config, road)


def check_traffic(config: EpisodeConfig, road: Road) -> None:
    """Traffic SUMO cannot warm up (a density it cannot insert, traffic that crashes on its own), refused
    before a campaign stores anything: its first sample's warm-up, which that sample plays anyway (cached)."""
    traffic_state(config.for_sample(0), road)


def simulate(
    config: EpisodeConfig,
    attack: AttackPlan | np.ndarray,
    *,
    road: Road | None = None,
    fcd_path: str | Path | None = None,
    gui: bool = False,
) -> Episode:
    """Play one episode in SUMO. ``attack``: the attacker's plan (`maneuvers.attack_plan`), or only its
    command at each step's start (``config.steps`` values in [-1, 1], NaN where the attacker cruises).
    A user's follower controller's error in it is raised."""
    plan = checked_plan(config, attack)
    road = road or config_road(config)
    types_file = check_episode(config, road)
    with fcd_file(fcd_path) as part:
        with open_world(config, road, [config], fcd_path=part, gui=gui, types_file=types_file) as world:
            result = play(world, [config], [plan])[0]
        if isinstance(result, Exception):
            raise result
    return result


def checked_plan(config: EpisodeConfig, attack: AttackPlan | np.ndarray) -> AttackPlan:
    """The attacker's plan, refused unless it is one command per step, each in [-1, 1] or NaN (it
    cruises): a command past full throttle or full brake would play physics no car has."""
    if not isinstance(config, EpisodeConfig):
        raise ConfigError("config", type(config).__name__, "an EpisodeConfig")
    try:
        plan = attack if isinstance(attack, AttackPlan) else AttackPlan(np.asarray(attack, dtype=float))
        u = np.asarray(plan.u, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError("attack", repr(attack)[:80], "an AttackPlan, or an array of commands") from None
    if u.shape != (config.steps,):
        raise ConfigError("attack", f"a signal of shape {u.shape}", f"{config.steps} commands, one per step of the episode")
    outside = ~np.isnan(u) & ~((u >= -1.0) & (u <= 1.0))
    if outside.any():
        k = int(np.argmax(outside))
        raise ConfigError("attack", f"{u[k]} at step {k}", "commands in [-1, 1], or NaN where the attacker cruises")
    return plan


@contextlib.contextmanager
def fcd_file(path: str | Path | None) -> Iterator[Path | None]:
    """Where SUMO writes an episode's FCD: a file beside ``path``, renamed to it once the episode ended and
    SUMO closed it whole. An interrupted or failed episode leaves nothing, and a file already at ``path``
    stays as it was; SUMO itself does not fail when it cannot write (a full disk), so the end is checked."""
    if path is None:
        yield None
        return
    path = Path(path)
    remove_stale_parts(path)
    part = part_of(path)
    try:
        yield part
        if not _ends_whole(part):
            raise SumoError(f"the FCD output {path} could not be written completely (is the disk full?)")
        name_fcd(part, part, path)
        os.replace(part, path)
    finally:
        part.unlink(missing_ok=True)


#: how far into an FCD file its header (SUMO's configuration, in a comment) reaches, at most
FCD_HEADER_BYTES = 1 << 16


def name_fcd(fcd: Path, written_as: str | Path, name: str | Path) -> None:
    """Make the header of an FCD file name the file ``name`` where it names ``written_as``: SUMO records the
    file it was told to write (a part, renamed once whole) in the configuration at the file's top. The
    header is edited in place (the line padded with spaces, inside its comment) where ``name`` is no longer,
    else the file is written anew beside itself and renamed over it."""
    old, new = (b'<fcd-output value="' + _xml_attribute(str(p)) + b'"/>' for p in (written_as, name))
    with open(fcd, "r+b") as fh:
        head = fh.read(FCD_HEADER_BYTES)
        at = head.find(old)
        if at < 0:  # no such header: nothing to name
            return
        if len(new) <= len(old):
            fh.seek(at)
            fh.write(new + b" " * (len(old) - len(new)))
            return
        fh.seek(at + len(old))
        anew = fcd.with_name(fcd.name + ".named")
        try:
            with open(anew, "wb") as out:
                out.write(head[:at] + new)
                while chunk := fh.read(1 << 20):
                    out.write(chunk)
            os.replace(anew, fcd)
        finally:
            anew.unlink(missing_ok=True)


def _xml_attribute(text: str) -> bytes:
    """An attribute's value as SUMO writes it into its XML: the five XML escapes, UTF-8."""
    for raw, escaped in (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ("'", "&apos;"), ('"', "&quot;")):
        text = text.replace(raw, escaped)
    return text.encode("utf-8")


def _ends_whole(fcd: Path) -> bool:
    try:
        with open(fcd, "rb") as fh:
            fh.seek(max(0, fcd.stat().st_size - 200))
            return b"</fcd-export>" in fh.read()
    except OSError:
        return False


# --- a batch: many episodes side by side in one SUMO ---------------------------------------------

def shares_sumo(config: EpisodeConfig) -> bool:
    """Whether the configuration's platoons may share one SUMO (see `simulate_batch`): not with traffic,
    whose every episode meets its own warm-up on the road alone."""
    return config.traffic is None and all(f.shares_sumo for f in followers_of(config))


def _one_at_a_time(config: EpisodeConfig, plans: Sequence[AttackPlan], road: Road | None, on_episode) -> list:
    """`simulate_batch`'s results, each episode played alone."""
    road = road or config_road(config)
    check_episode(config, road)
    results: list = []
    for i, plan in enumerate(plans):
        try:
            result = simulate(config, plan, road=road)
        except (SumoError, ConfigError):
            raise  # as in a batch: SUMO's failure, or a configuration it cannot play, ends them all
        except Exception as exc:  # a user's controller: this episode's error, as alone
            result = exc
        results.append(result)
        if on_episode:
            on_episode(i, result)
    return results


def drives_one_lane(config: EpisodeConfig) -> bool:
    """Whether an episode drives the platoon's lane alone: in the paper's column (no lane change), among no traffic."""
    return not config.maneuver_class.lateral and config.traffic is None


def simulate_batch(config: EpisodeConfig | Sequence[EpisodeConfig], plans: Sequence[AttackPlan], *,
                   road: Road | None = None,
                   on_episode: Callable[[int, "Episode | Exception"], None] | None = None) -> list["Episode | Exception"]:
    """Play many episodes side by side in one SUMO instance, each platoon on its own copy of the road
    (`scenarios.batch_road`), commanded together (`batch.PlatoonBatch`). ``config``: one for every
    episode, or one per plan, differing at most in setpoint, target speed and start from rest or
    steady (`batch.batch_key`: several campaigns' episodes in one SUMO).

    Each result is bit for bit what `simulate` gives for the same plan alone: the episode, or the
    exception a user's follower controller raised in it (alone it would end that episode). An episode
    that ends (its first collision) leaves SUMO at once and costs nothing more; ``on_episode(i, result)``
    hears of it then. Followers whose SUMO model draws from SUMO's random streams (`carfollowing.shares_sumo`)
    would draw differently beside other platoons: their episodes play one at a time, in turn, as do the
    episodes on a road whose copies netconvert does not build alike (`scenarios.batch_road`).
    """
    if not plans:
        return []
    if len(plans) > MAX_COPIES:
        raise ValueError(f"a batch of {len(plans)} episodes; allowed: at most {MAX_COPIES}")
    configs = episode_configs(config, len(plans))
    plans = [checked_plan(c, p) for c, p in zip(configs, plans)]
    config = configs[0]
    distinct = list({id(c): c for c in configs}.values())
    batched = shares_sumo(config)
    if batched and (road is None or road.copies < len(plans) and not road.copies_unlike):
        road = batch_road(config.network, len(plans), route=config.route, lane=config.lane,  # alone where copies differ
                          given=config.network_given, one_lane=drives_one_lane(config))
    if not batched or road.copies < len(plans):
        alone = road if road is not None and road.copies == 1 else None
        if len(distinct) == 1:
            return _one_at_a_time(config, plans, alone, on_episode)
        results = []
        for i, (c, plan) in enumerate(zip(configs, plans)):  # each with its own configuration, in turn
            results += _one_at_a_time(c, [plan], alone, on_episode and (lambda _, r, i=i: on_episode(i, r)))
        return results
    types_file = check_episode(config, road)
    for c in distinct[1:]:
        check_episode(c, road)
    with open_world(config, road, configs, types_file=types_file) as world:
        return play(world, configs, plans, on_episode=on_episode)
