"""The results database: refuses what is not ours, never corrupts, never counts twice."""

from __future__ import annotations

import sqlite3

import pytest

from d4sumo.store import SCHEMA_VERSION, Store, StoreError

DEFINITION = {"config": {}, "attack": {"family": "knots"}, "optimizer": "bo", "seed": 1, "spec": {}}


def test_samples_round_trip_and_are_never_counted_twice(tmp_path):
    with Store(tmp_path / "r.sqlite") as store:
        cid = store.open_campaign(DEFINITION, 100)
        assert store.open_campaign(DEFINITION, 200) == cid  # same definition: same campaign
        assert store.campaign(cid).budget == 200
        sid = store.add_sample(cid, 0, [0.5, -1.0], 0.25, "success",
                               {"pair": "v1-v2", "time_s": 3.0, "position_m": 50.0, "speed_diff_kmh": 9.0}, {"v0-v1": 1.0}, 0.01)
        with pytest.raises(StoreError, match="already has sample 0"):
            store.add_sample(cid, 0, [0.5, -1.0], 0.25, "success", None, None, 0.01)
        row = store.sample(sid)
        assert row.params == (0.5, -1.0) and row.pair == "v1-v2" and row.min_gaps == {"v0-v1": 1.0}
        assert len(store.samples(cid)) == 1


def test_a_file_that_is_not_sqlite_is_refused_untouched(tmp_path):
    path = tmp_path / "notes.sqlite"
    path.write_bytes(b"my notes, not a database\n" * 10)
    before = path.read_bytes()
    with pytest.raises(StoreError, match="not a d4sumo results database"):
        Store(path)
    assert path.read_bytes() == before


def test_another_programs_sqlite_is_refused_untouched(tmp_path):
    path = tmp_path / "other.sqlite"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE measurements (t REAL)")
    db.commit()
    db.close()
    before = path.read_bytes()
    with pytest.raises(StoreError, match="tables: measurements"):
        Store(path)
    assert path.read_bytes() == before


def test_a_database_from_another_schema_version_is_refused_untouched(tmp_path):
    path = tmp_path / "old.sqlite"
    Store(path).close()
    db = sqlite3.connect(path)
    db.execute("UPDATE meta SET value = '0' WHERE key = 'schema_version'")
    db.commit()
    db.close()
    before = path.read_bytes()
    with pytest.raises(StoreError, match=f"schema 0, this d4sumo .* reads schema {SCHEMA_VERSION}"):
        Store(path)
    assert path.read_bytes() == before


def test_opening_a_missing_database_for_reading_is_an_error(tmp_path):
    with pytest.raises(StoreError, match="no such results database"):
        Store(tmp_path / "nope.sqlite", create=False)
    assert not (tmp_path / "nope.sqlite").exists()
