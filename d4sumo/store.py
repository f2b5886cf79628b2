"""Results database: one embedded SQLite file holding campaigns and their samples.

Every sample is committed as soon as it finishes; (campaign, index) is unique, so a resumed
campaign never counts a sample twice. A campaign is identified by a hash of its definition
(configuration, attack, optimiser, seed, specification), not by its budget: running it again with
the same or a larger budget resumes it. Several processes may write to one file (WAL journal).
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from . import __version__
from .errors import D4sumoError

APP_ID = "d4sumo"
SCHEMA_VERSION = 1

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS campaign (
    id INTEGER PRIMARY KEY,
    key TEXT NOT NULL UNIQUE,
    definition TEXT NOT NULL,          -- JSON: config, attack, optimizer, seed, spec
    budget INTEGER NOT NULL,           -- samples asked for (the largest so far)
    version TEXT NOT NULL,             -- d4sumo version that created it
    created_at TEXT NOT NULL,
    sweep TEXT                         -- name of the sweep that owns it, if any
);
CREATE TABLE IF NOT EXISTS sample (
    id INTEGER PRIMARY KEY,
    campaign_id INTEGER NOT NULL REFERENCES campaign(id),
    idx INTEGER NOT NULL,              -- 0-based order within the campaign
    params TEXT NOT NULL,              -- JSON list: the attack's parameter vector
    robustness REAL,                   -- NULL for an errored sample
    outcome TEXT NOT NULL,             -- success | attacker_crash | no_crash | error
    pair TEXT, time_s REAL, position_m REAL, speed_diff_kmh REAL,   -- first collision
    min_gaps TEXT,                     -- JSON: pair -> minimum gap [m]
    wall_s REAL NOT NULL,              -- simulation + scoring time
    error TEXT,
    UNIQUE (campaign_id, idx)
);
"""


class StoreError(D4sumoError):
    """The database is not ours, is from another schema version, or disagrees with a campaign."""


@dataclass(frozen=True)
class SampleRow:
    id: int
    campaign_id: int
    index: int
    params: tuple[float, ...]
    robustness: float | None
    outcome: str
    pair: str | None
    time_s: float | None
    position_m: float | None
    speed_diff_kmh: float | None
    min_gaps: dict[str, float]
    wall_s: float
    error: str | None

    @property
    def collision(self) -> dict | None:
        return collision_dict(self.pair, self.time_s, self.position_m, self.speed_diff_kmh)


@dataclass(frozen=True)
class CampaignRow:
    id: int
    key: str
    definition: dict[str, Any]
    budget: int
    version: str
    created_at: str
    sweep: str | None


def collision_dict(pair: str | None, time_s, position_m, speed_diff_kmh) -> dict | None:
    """A stored first collision as the runner reports it, or None when there was none."""
    if pair is None:
        return None
    return {"pair": pair, "time_s": time_s, "position_m": position_m, "speed_diff_kmh": speed_diff_kmh}


def campaign_key(definition: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(definition, sort_keys=True).encode()).hexdigest()[:20]


class Store:
    def __init__(self, path: str | Path, *, create: bool = True):
        self.path = Path(path)
        exists = self.path.exists() and self.path.stat().st_size > 0
        if not exists and not create:
            raise StoreError(f"{self.path}: no such results database")
        if self.path.is_dir():
            raise StoreError(f"{self.path}: is a folder, not a results database")
        try:
            self.db = sqlite3.connect(self.path, timeout=60.0, isolation_level=None)
            self.db.execute("PRAGMA busy_timeout = 60000")
            if exists:
                self._check_ours()
            else:
                self._create()
            self.db.execute("PRAGMA journal_mode = WAL")
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self.path}: not a d4sumo results database ({exc})") from None

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _create(self) -> None:
        self.db.executescript(SCHEMA)  # idempotent; executescript commits on its own
        with self._transaction():
            self.db.execute("INSERT OR IGNORE INTO meta VALUES ('app', ?), ('schema_version', ?), ('created_by', ?)",
                            (APP_ID, str(SCHEMA_VERSION), __version__))

    def _check_ours(self) -> None:
        tables = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "meta" not in tables:
            raise StoreError(f"{self.path}: not a d4sumo results database (tables: {', '.join(sorted(tables)) or 'none'})")
        meta = dict(self.db.execute("SELECT key, value FROM meta"))
        if meta.get("app") != APP_ID:
            raise StoreError(f"{self.path}: not a d4sumo results database (app {meta.get('app')!r})")
        version = int(meta.get("schema_version", "0"))
        if version != SCHEMA_VERSION:
            raise StoreError(
                f"{self.path}: written with results schema {version}, this d4sumo ({__version__}) reads schema "
                f"{SCHEMA_VERSION}; nothing was changed. Use the d4sumo version that wrote it, or a new database"
            )

    def _transaction(self):
        db = self.db

        class _Tx:
            def __enter__(self):
                db.execute("BEGIN IMMEDIATE")

            def __exit__(self, exc_type, *rest):
                db.execute("ROLLBACK" if exc_type else "COMMIT")

        return _Tx()

    # --- campaigns ------------------------------------------------------------------------------

    def open_campaign(self, definition: dict[str, Any], budget: int, sweep: str | None = None) -> int:
        """The id of the campaign with this definition, created if new; its budget grows to ``budget``."""
        key = campaign_key(definition)
        with self._transaction():
            row = self.db.execute("SELECT id, budget FROM campaign WHERE key = ?", (key,)).fetchone()
            if row is None:
                cur = self.db.execute(
                    "INSERT INTO campaign (key, definition, budget, version, created_at, sweep) VALUES (?, ?, ?, ?, ?, ?)",
                    (key, json.dumps(definition, sort_keys=True), budget, __version__, time.strftime("%Y-%m-%dT%H:%M:%S"), sweep),
                )
                return int(cur.lastrowid)
            if budget > row[1]:
                self.db.execute("UPDATE campaign SET budget = ? WHERE id = ?", (budget, row[0]))
            return int(row[0])

    def campaigns(self, sweep: str | None = None) -> list[CampaignRow]:
        query = "SELECT id, key, definition, budget, version, created_at, sweep FROM campaign"
        rows = self.db.execute(query + (" WHERE sweep = ?" if sweep else "") + " ORDER BY id", (sweep,) if sweep else ())
        return [CampaignRow(r[0], r[1], json.loads(r[2]), r[3], r[4], r[5], r[6]) for r in rows]

    def campaign(self, campaign_id: int) -> CampaignRow:
        for row in self.campaigns():
            if row.id == campaign_id:
                return row
        raise StoreError(f"{self.path}: no campaign {campaign_id}")

    def meta(self) -> dict[str, str]:
        return dict(self.db.execute("SELECT key, value FROM meta"))

    def set_meta(self, key: str, value: str) -> None:
        with self._transaction():
            self.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))

    # --- samples --------------------------------------------------------------------------------

    def add_sample(self, campaign_id: int, index: int, params, robustness: float | None, outcome: str,
                   collision: dict | None, min_gaps: dict | None, wall_s: float, error: str | None = None) -> int:
        c = collision or {}
        try:
            cur = self.db.execute(
                "INSERT INTO sample (campaign_id, idx, params, robustness, outcome, pair, time_s, position_m, "
                "speed_diff_kmh, min_gaps, wall_s, error) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (campaign_id, index, json.dumps([float(v) for v in params]), robustness, outcome, c.get("pair"),
                 c.get("time_s"), c.get("position_m"), c.get("speed_diff_kmh"),
                 json.dumps(min_gaps) if min_gaps is not None else None, wall_s, error),
            )
        except sqlite3.IntegrityError:
            raise StoreError(f"{self.path}: campaign {campaign_id} already has sample {index}") from None
        return int(cur.lastrowid)

    _SAMPLE_COLUMNS = ("SELECT id, campaign_id, idx, params, robustness, outcome, pair, time_s, position_m, "
                       "speed_diff_kmh, min_gaps, wall_s, error FROM sample")

    @staticmethod
    def _sample_row(r) -> SampleRow:
        return SampleRow(r[0], r[1], r[2], tuple(json.loads(r[3])), r[4], r[5], r[6], r[7], r[8], r[9],
                         json.loads(r[10]) if r[10] else {}, r[11], r[12])

    def samples(self, campaign_id: int | None = None) -> list[SampleRow]:
        return list(self.iter_samples(campaign_id))

    def iter_samples(self, campaign_id: int | None = None) -> Iterator[SampleRow]:
        if campaign_id is None:
            rows = self.db.execute(self._SAMPLE_COLUMNS + " ORDER BY campaign_id, idx")
        else:
            rows = self.db.execute(self._SAMPLE_COLUMNS + " WHERE campaign_id = ? ORDER BY idx", (campaign_id,))
        return (self._sample_row(r) for r in rows)

    def sample(self, sample_id: int) -> SampleRow:
        row = self.db.execute(self._SAMPLE_COLUMNS + " WHERE id = ?", (sample_id,)).fetchone()
        if row is None:
            raise StoreError(f"{self.path}: no sample {sample_id}")
        return self._sample_row(row)
