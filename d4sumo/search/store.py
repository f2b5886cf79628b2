"""Results database: one embedded SQLite file holding campaigns and their samples.

Every sample is committed as soon as it finishes; (campaign, index) is unique, so a resumed
campaign never counts a sample twice. A campaign is identified by a hash of its definition
(configuration, attack, optimiser, seed, specification), not by its budget: running it again with
the same or a larger budget resumes it.

One process writes a database at a time: a writer holds an exclusive lock on the file for as long as
it has it open (released by the system if the process dies), so a second writer is refused clearly.
Readers (`Store(path, create=False)`) open it read-only and leave no side files. The schema is
created in one transaction, so a kill while creating leaves an empty file that the next run fills.
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import json
import math
import os
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator
from urllib.parse import quote

from .. import __version__
from ..errors import D4sumoError, refusal

APP_ID = "d4sumo"
SCHEMA_VERSION = 2  # 2: collisions are any overlap, actuator without wind-up; no WAL journal
OUTCOMES = ("success", "attacker_crash", "no_crash", "error")

SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE campaign (
    id INTEGER PRIMARY KEY,
    key TEXT NOT NULL UNIQUE,
    definition TEXT NOT NULL,          -- JSON: config, attack, optimizer, seed, spec
    budget INTEGER NOT NULL,           -- samples asked for (the largest so far)
    version TEXT NOT NULL,             -- d4sumo version that created it
    created_at TEXT NOT NULL,
    sweep TEXT                         -- name of the sweep that owns it, if any
);
CREATE TABLE sample (
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
TABLES = {"meta", "campaign", "sample"}


class StoreError(D4sumoError):
    """The database is not ours, is from another schema version, or disagrees with a campaign."""


class DefinitionError(StoreError):
    """A stored campaign definition does not describe a valid campaign; ``field`` names the bad value."""

    def __init__(self, message: str, field: str | None = None):
        super().__init__(message)
        self.field = field


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


def _guarded(method):
    """sqlite's errors on a damaged file become one clear StoreError, whatever the method."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self.path}: damaged or unreadable results database ({exc})") from None

    return wrapper


class Store:
    """A results database. ``Store(path)`` opens it for writing (created if new; one writer at a
    time); ``Store(path, create=False)`` opens an existing one read-only."""

    def __init__(self, path: str | Path, *, create: bool = True,
                 check_definition: Callable[[dict[str, Any], str], None] | None = None):
        """``check_definition(definition, where)``: raises a `DefinitionError` for a campaign definition
        that describes no valid campaign (`campaign.check_definition`, which imports nothing); without
        it a definition is checked for its parts only."""
        self.path = Path(path)
        self.readonly = not create
        self.check_definition = check_definition
        self._lock_fd: int | None = None
        if self.path.is_dir():
            raise StoreError(refusal("results database", str(self.path), "a database file (this is a folder)"))
        if self.readonly and not self.path.is_file():
            raise StoreError(refusal("results database", str(self.path), "a results database d4sumo wrote (no such file)"))
        if not self.readonly and not self.path.parent.is_dir():
            raise StoreError(refusal("results database", str(self.path),
                                     f"a file in an existing folder ({self.path.parent} does not exist)"))
        try:
            if self.readonly:
                uri = f"file:{quote(str(self.path.resolve()))}?mode=ro"
                self.db = sqlite3.connect(uri, uri=True, timeout=60.0, isolation_level=None)
            else:
                self._lock()
                self.db = sqlite3.connect(self.path, timeout=60.0, isolation_level=None)
            self.db.execute("PRAGMA busy_timeout = 60000")
            tables = self._tables()
            if not tables and not self.readonly:
                self._create()  # new, empty, or left empty by a kill during creation
            else:
                self._check_ours(tables)
                if not self.readonly:
                    self.check_all()
        except sqlite3.DatabaseError as exc:
            self.close()
            raise StoreError(f"{self.path}: not a d4sumo results database ({exc})") from None
        except BaseException:
            self.close()
            raise

    def _lock(self) -> None:
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise StoreError(f"{self.path}: cannot open for writing ({exc.strerror})") from None
        try:
            # flock, not fcntl byte-range locks: those are SQLite's own and do not interact with flock
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise StoreError(f"{self.path}: another d4sumo command is writing to it; nothing was changed. "
                             "Wait for it to finish, or use another --db") from None
        self._lock_fd = fd

    def _tables(self) -> set[str]:
        return {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}

    def close(self) -> None:
        db = getattr(self, "db", None)
        if db is not None:
            db.close()
            self.db = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the lock
            self._lock_fd = None

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _create(self) -> None:
        # One transaction: a kill part-way leaves a hot journal that SQLite rolls back on the next
        # open, back to an empty file that the next writer creates afresh.
        statements = [f"{st.strip()};" for st in SCHEMA.split(";") if st.strip()]
        script = "BEGIN IMMEDIATE;\n" + "\n".join(statements) + "\n" + (
            "INSERT INTO meta VALUES ('app', {}), ('schema_version', {}), ('created_by', {});\nCOMMIT;".format(
                *(_sql_string(v) for v in (APP_ID, str(SCHEMA_VERSION), __version__))))
        try:
            self.db.executescript(script)
        except BaseException:
            if self.db.in_transaction:
                self.db.execute("ROLLBACK")
            raise

    def _check_ours(self, tables: set[str]) -> None:
        if "meta" not in tables:
            raise StoreError(f"{self.path}: not a d4sumo results database (tables: {', '.join(sorted(tables)) or 'none'})")
        meta = dict(self.db.execute("SELECT key, value FROM meta"))
        if meta.get("app") != APP_ID:
            raise StoreError(f"{self.path}: not a d4sumo results database (app {meta.get('app')!r})")
        raw = meta.get("schema_version")
        try:
            version = int(raw)
        except (TypeError, ValueError):
            raise StoreError(f"{self.path}: damaged results database (schema version {raw!r} is not a number)") from None
        if version != SCHEMA_VERSION:
            raise StoreError(
                f"{self.path}: written with results schema {version}, this d4sumo ({__version__}) reads schema "
                f"{SCHEMA_VERSION}; nothing was changed. Use the d4sumo version that wrote it, or a new database"
            )
        missing = TABLES - tables
        if missing:
            raise StoreError(f"{self.path}: damaged results database (missing tables: {', '.join(sorted(missing))})")
        problem = self.db.execute("PRAGMA quick_check").fetchone()[0]
        if problem != "ok":
            raise StoreError(f"{self.path}: damaged results database ({problem})")

    def _transaction(self):
        db = self.db

        class _Tx:
            def __enter__(self):
                db.execute("BEGIN IMMEDIATE")

            def __exit__(self, exc_type, *rest):
                db.execute("ROLLBACK" if exc_type else "COMMIT")

        return _Tx()

    # --- campaigns ------------------------------------------------------------------------------

    @_guarded
    def find_campaign(self, definition: dict[str, Any]) -> int | None:
        """The id of the campaign with this definition, if stored (reads only)."""
        row = self.db.execute("SELECT id FROM campaign WHERE key = ?", (campaign_key(definition),)).fetchone()
        return None if row is None else int(row[0])

    def check_all(self) -> None:
        """Read and check every campaign and sample: a writer refuses a damaged database before
        writing anything to it."""
        self.campaigns()
        for _ in self.iter_samples():
            pass

    @_guarded
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

    @_guarded
    def campaigns(self, sweep: str | None = None) -> list[CampaignRow]:
        query = "SELECT id, key, definition, budget, version, created_at, sweep FROM campaign"
        rows = self.db.execute(query + (" WHERE sweep = ?" if sweep else "") + " ORDER BY id", (sweep,) if sweep else ())
        return [self._campaign_row(r) for r in rows]

    def _campaign_row(self, r) -> CampaignRow:
        definition = _json(r[2], dict)
        if definition is None or not {"config", "attack", "optimizer", "seed", "spec"} <= set(definition):
            raise StoreError(f"{self.path}: damaged results database (campaign {r[0]}: its definition is not valid JSON "
                             "with config, attack, optimizer, seed and spec)")
        if not isinstance(r[3], int) or r[3] < 0:
            raise StoreError(f"{self.path}: damaged results database (campaign {r[0]}: budget {r[3]!r})")
        if self.check_definition is not None:  # every value checked
            self.check_definition(definition, f"{self.path}: campaign {r[0]}")
        return CampaignRow(r[0], r[1], definition, r[3], r[4], r[5], r[6])

    def campaign(self, campaign_id: int) -> CampaignRow:
        for row in self.campaigns():
            if row.id == campaign_id:
                return row
        raise StoreError(f"{self.path}: no campaign {campaign_id}")

    @_guarded
    def meta(self) -> dict[str, str]:
        return dict(self.db.execute("SELECT key, value FROM meta"))

    @_guarded
    def set_meta(self, key: str, value: str) -> None:
        with self._transaction():
            self.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))

    # --- samples --------------------------------------------------------------------------------

    def add_sample(self, campaign_id: int, index: int, params, robustness: float | None, outcome: str,
                   collision: dict | None, min_gaps: dict | None, wall_s: float, error: str | None = None) -> int:
        return self.add_samples(campaign_id, [(index, params, robustness, outcome, collision, min_gaps, wall_s, error)])[0]

    @_guarded
    def add_samples(self, campaign_id: int, samples: list[tuple]) -> list[int]:
        """Store samples (index, params, robustness, outcome, collision, min_gaps, wall_s, error) of one
        campaign in one transaction: all or none; returns their row ids."""
        return self.add_samples_of([(campaign_id, samples)])[0]

    @_guarded
    def add_samples_of(self, campaigns: list[tuple[int, list[tuple]]]) -> list[list[int]]:
        """Store the samples of several campaigns (campaign id, its samples as `add_samples` takes them) in one
        transaction: all or none (a sweep's client writes what its workers returned over a moment at once, one
        disk sync for them all); each campaign's row ids."""
        ids: list[list[int]] = []
        with self._transaction():
            for campaign_id, samples in campaigns:
                ids.append([])
                for index, params, robustness, outcome, collision, min_gaps, wall_s, error in samples:
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
                    ids[-1].append(int(cur.lastrowid))
        return ids

    _SAMPLE_COLUMNS = ("SELECT s.id, s.campaign_id, s.idx, s.params, s.robustness, s.outcome, s.pair, s.time_s, s.position_m, "
                       "s.speed_diff_kmh, s.min_gaps, s.wall_s, s.error, c.id FROM sample s LEFT JOIN campaign c ON c.id = s.campaign_id")

    def _sample_row(self, r) -> SampleRow:
        """A stored row, checked: a damaged one is a clear error, never a wrong result."""
        def bad(what: str) -> StoreError:
            return StoreError(f"{self.path}: damaged results database (sample {r[0]}: {what})")

        if r[13] is None:
            raise bad(f"it belongs to no campaign (campaign_id {r[1]!r})")
        params = _json(r[3], list)
        if params is None or not params or not all(_finite(v) for v in params):
            raise bad(f"parameters {r[3]!r} are not a JSON list of numbers")
        if r[5] not in OUTCOMES:
            raise bad(f"unknown outcome {r[5]!r}")
        if r[5] == "error":
            if r[4] is not None:
                raise bad("an errored sample with a robustness")
        elif not _finite(r[4]):
            raise bad(f"robustness {r[4]!r}")
        min_gaps = {} if r[10] is None else _json(r[10], dict)
        if min_gaps is None or not all(_finite(v) for v in min_gaps.values()):
            raise bad(f"minimum gaps {r[10]!r} are not a JSON object of numbers")
        if (r[6] is None) != (r[5] in ("no_crash", "error")):
            raise bad(f"outcome {r[5]} with collision {r[6]!r}")
        if r[6] is not None and not all(_finite(v) for v in r[7:10]):
            raise bad("a collision without time, position or speed difference")
        if not _finite(r[11]) or not isinstance(r[2], int):
            raise bad("index or wall time")
        return SampleRow(r[0], r[1], r[2], tuple(float(v) for v in params), r[4], r[5], r[6], r[7], r[8], r[9],
                         min_gaps, r[11], r[12])

    def samples(self, campaign_id: int | None = None) -> list[SampleRow]:
        return list(self.iter_samples(campaign_id))

    def iter_samples(self, campaign_id: int | None = None) -> Iterator[SampleRow]:
        try:
            if campaign_id is None:
                rows = self.db.execute(self._SAMPLE_COLUMNS + " ORDER BY s.campaign_id, s.idx")
            else:
                rows = self.db.execute(self._SAMPLE_COLUMNS + " WHERE s.campaign_id = ? ORDER BY s.idx", (campaign_id,))
            for r in rows:
                yield self._sample_row(r)
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self.path}: damaged or unreadable results database ({exc})") from None

    @_guarded
    def sample(self, sample_id: int) -> SampleRow:
        # an id past SQLite's 64-bit integers is no stored sample (sqlite3 would raise OverflowError)
        row = (self.db.execute(self._SAMPLE_COLUMNS + " WHERE s.id = ?", (sample_id,)).fetchone()
               if -2**63 <= sample_id < 2**63 else None)
        if row is None:
            last = self.db.execute("SELECT MIN(id), MAX(id) FROM sample").fetchone()
            held = f"it holds sample ids {last[0]}..{last[1]}" if last[0] is not None else "it holds no samples"
            raise StoreError(f"{self.path}: no sample {sample_id} ({held})")
        return self._sample_row(row)

    @_guarded
    def sweep_counts(self, sweep: str) -> tuple[int, int]:
        """(samples stored, successes stored) of a sweep's campaigns."""
        row = self.db.execute(
            "SELECT COUNT(*), COALESCE(SUM(s.outcome = 'success'), 0) FROM sample s JOIN campaign c ON s.campaign_id = c.id "
            "WHERE c.sweep = ?", (sweep,)).fetchone()
        return int(row[0]), int(row[1])

    @_guarded
    def count_samples(self, campaign_id: int) -> int:
        return int(self.db.execute("SELECT COUNT(*) FROM sample WHERE campaign_id = ?", (campaign_id,)).fetchone()[0])


def _json(text: Any, kind: type) -> Any:
    """JSON text decoded if it is of ``kind``, else None."""
    if not isinstance(text, str):
        return None
    try:
        value = json.loads(text)
    except ValueError:
        return None
    return value if isinstance(value, kind) else None


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _sql_string(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"
