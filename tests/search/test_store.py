"""The results database: refuses what is not ours, never corrupts, never counts twice."""

from __future__ import annotations

import sqlite3

import pytest

from d4sumo.search.campaign import Campaign
from d4sumo.search.store import SCHEMA_VERSION, Store, StoreError

DEFINITION = Campaign(seed=1).definition()


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
    """Version 1 databases (WAL journal, collisions as SUMO reported them) are refused, not mixed in."""
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
    with pytest.raises(StoreError, match=r"results database: got '.*nope.sqlite'; allowed: a results database d4sumo wrote \(no such file\)"):
        Store(tmp_path / "nope.sqlite", create=False)
    assert not (tmp_path / "nope.sqlite").exists()


def test_a_kill_in_the_middle_of_creating_the_schema_leaves_a_database_the_next_run_creates(tmp_path):
    """Regression: kills in the first milliseconds left tables without the meta row, refused ever after."""
    import subprocess
    import sys

    path = tmp_path / "r.sqlite"
    code = f"""
import os, d4sumo.search.store as st
real = st.Store._create
def dying(self):
    self.db.executescript("BEGIN IMMEDIATE; CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL); "
                          "CREATE TABLE campaign (id INTEGER PRIMARY KEY);")
    os._exit(9)  # killed: schema half made, not committed
st.Store._create = dying
st.Store({str(path)!r})
"""
    assert subprocess.run([sys.executable, "-c", code]).returncode == 9
    assert path.exists()
    with Store(path) as store:  # rolled back and created afresh
        assert store.meta()["schema_version"] == str(SCHEMA_VERSION)
        assert store.campaigns() == []


def test_a_second_writer_is_refused_and_readers_are_not(tmp_path):
    path = tmp_path / "r.sqlite"
    with Store(path) as writer:
        writer.open_campaign(DEFINITION, 10)
        with pytest.raises(StoreError, match="another d4sumo command is writing to it"):
            Store(path)
        with Store(path, create=False) as reader:
            assert len(reader.campaigns()) == 1
    with Store(path):  # released on close
        pass


def test_readers_open_read_only_and_leave_no_side_files(tmp_path):
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        store.add_sample(store.open_campaign(DEFINITION, 10), 0, [0.1], -0.5, "no_crash", None, {"v0-v1": 3.0}, 0.01)
    before = path.read_bytes()
    with Store(path, create=False) as reader:
        assert len(reader.samples()) == 1
        with pytest.raises(sqlite3.OperationalError, match="readonly"):
            reader.db.execute("DELETE FROM sample")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.sqlite"]


def damage(path, sql, *params):
    db = sqlite3.connect(path)
    db.execute(sql, params)
    db.commit()
    db.close()


@pytest.fixture
def one_sample(tmp_path):
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        cid = store.open_campaign(DEFINITION, 10)
        store.add_sample(cid, 0, [0.1, 0.2], 0.3, "success",
                         {"pair": "v1-v2", "time_s": 3.0, "position_m": 50.0, "speed_diff_kmh": 9.0}, {"v0-v1": 1.0}, 0.01)
    return path


@pytest.mark.parametrize(
    "sql, message",
    [
        ("UPDATE sample SET params = '[0.1, '", "parameters"),
        ("UPDATE sample SET params = '[\"a\"]'", "parameters"),
        ("UPDATE sample SET outcome = 'victory'", "unknown outcome 'victory'"),
        ("UPDATE sample SET min_gaps = '{bad json'", "minimum gaps"),
        ("UPDATE sample SET pair = NULL", "outcome success with collision None"),
        ("UPDATE sample SET robustness = NULL", "robustness None"),
        ("UPDATE sample SET campaign_id = 7", "belongs to no campaign"),
        ("UPDATE campaign SET definition = '{\"config\": 1'", "definition is not valid JSON"),
        ("UPDATE meta SET value = 'two' WHERE key = 'schema_version'", "schema version 'two' is not a number"),
        ("DROP TABLE sample", "missing tables: sample"),
    ],
)
def test_a_damaged_row_or_table_is_a_clear_error_when_read(one_sample, sql, message):
    damage(one_sample, sql)
    before = one_sample.read_bytes()
    with pytest.raises(StoreError, match=message):
        with Store(one_sample, create=False) as store:
            store.campaigns()
            store.samples()
    with pytest.raises(StoreError, match=message):
        with Store(one_sample) as store:
            store.campaigns()
            store.samples()
    assert one_sample.read_bytes() == before


def test_a_malformed_page_is_a_clear_error(one_sample):
    data = bytearray(one_sample.read_bytes())
    page = 4096
    data[2 * page + 10: 2 * page + 400] = b"\xff" * 390  # garble the second page's cells
    one_sample.write_bytes(bytes(data))
    with pytest.raises(StoreError, match="damaged|not a d4sumo"):
        with Store(one_sample, create=False) as store:
            store.samples()


def test_a_campaign_of_a_controller_not_importable_here_is_still_readable(tmp_path):
    """A database made with a user's own controller can be exported and reported elsewhere."""
    import copy

    definition = copy.deepcopy(DEFINITION)
    definition["config"]["controller"]["class"] = "gone_package.module:MyController"
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        store.open_campaign(definition, 10)
    with Store(path, create=False) as store:
        assert store.campaigns()[0].definition["config"]["controller"]["class"] == "gone_package.module:MyController"
    # the same in a mixed platoon: any follower's controller may be one of the user's own
    mixed = copy.deepcopy(DEFINITION)
    mixed["config"]["controller"] = [{"class": "sumo:ACC"}, {"class": "gone_package.module:MyController", "gain": 1},
                                     {"class": "switching"}]
    with Store(tmp_path / "m.sqlite") as store:
        store.open_campaign(mixed, 10)
    with Store(tmp_path / "m.sqlite", create=False) as store:
        assert store.campaigns()[0].definition["config"]["controller"][1]["class"] == "gone_package.module:MyController"
    # while a bad value of a follower's controller is damage, named by its follower
    from d4sumo.errors import ConfigError
    from d4sumo.model.config import EpisodeConfig

    with pytest.raises(ConfigError) as err:
        EpisodeConfig.from_dict({"controller": ["switching", {"class": "switching", "acc_kp": -1}, "timegap"]})
    assert err.value.field == "controller.v2.acc_kp"
