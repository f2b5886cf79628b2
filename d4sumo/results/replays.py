"""A stored sample played again: its campaign's evaluator, rebuilt from the database (`evaluator_of`), and its
replay into an FCD file, read as the time-space diagram draws it (`replay_to_fcd`)."""

from __future__ import annotations

from pathlib import Path

from ..engine.simulation import name_fcd
from ..errors import ConfigError
from ..search.campaign import Campaign, open_store
from ..search.runner import Evaluator
from . import timespace
from .records import Record


def evaluator_of(record: Record) -> Evaluator:
    """The evaluator of a stored sample's campaign, ready to replay it (its controllers loaded, its
    parameters checked: a damaged row says which sample of which database)."""
    with open_store(record.db, create=False) as store:
        definition = store.campaign(record.campaign_id).definition
    campaign = Campaign.from_definition(definition, where=f"{record.db}: campaign {record.campaign_id}", imports=True)
    evaluator = Evaluator(campaign)
    try:
        evaluator.plan(record.params)
    except ConfigError as exc:  # a damaged database: say which sample of which
        raise ConfigError(f"{record.db}: sample {record.sample_id}: {exc.field}", exc.given, exc.allowed) from None
    return evaluator


def replay_to_fcd(record: Record, fcd_path: str | Path, name: str | Path | None = None) -> dict:
    """Re-simulate a stored sample into an FCD file; returns the parsed FCD. ``name``: where the file will
    be once moved (a report's, built in a folder beside its own), for its header to name."""
    evaluator = evaluator_of(record)
    episode = evaluator.simulate(record.index, record.params, fcd_path=fcd_path)
    if name is not None:
        name_fcd(Path(fcd_path), fcd_path, name)
    fcd = timespace.read_fcd(fcd_path, evaluator.road.platoon_lanes)
    fcd.signals = episode.signals  # the lights along the route, as the replay recorded them
    said = timespace.said_track(episode.trace, fcd)
    if said is not None:  # a message attack: what the liar's beacons said, beside where it was
        fcd[said[0]] = said[1]
    return fcd
