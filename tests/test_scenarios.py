"""Network variants: plain node/edge XML built by netconvert and cached."""

from __future__ import annotations

import shutil

import pytest

from d4sumo.errors import ConfigError, SumoError
from d4sumo.scenarios import SCENARIOS_DIR, build_road, list_scenarios


def test_at_least_three_variants_ship():
    names = list_scenarios()
    assert {"highway_4lane", "highway_1lane"} <= set(names) and len(names) >= 3
    for name in names:
        assert (SCENARIOS_DIR / name / "README.md").is_file()


@pytest.mark.sumo
@pytest.mark.parametrize("name", list_scenarios())
def test_every_variant_builds_into_a_straight_road(name, tmp_path):
    road = build_road(name, cache_dir=tmp_path)
    assert road.net_file.is_file() and road.route_edges
    assert road.length_m >= 3000 and road.speed_limit_mps > 30


@pytest.mark.sumo
def test_the_net_is_cached_and_rebuilt_when_the_variant_changes(tmp_path):
    variant = tmp_path / "mine"
    shutil.copytree(SCENARIOS_DIR / "highway_1lane", variant)
    cache = tmp_path / "cache"
    first = build_road(str(variant), cache_dir=cache)
    mtime = first.net_file.stat().st_mtime_ns
    assert build_road(str(variant), cache_dir=cache).net_file.stat().st_mtime_ns == mtime
    edges = variant / "highway.edg.xml"
    edges.write_text(edges.read_text().replace('speed="40"', 'speed="30"'))
    changed = build_road(str(variant), cache_dir=cache)
    assert changed.net_file != first.net_file and changed.speed_limit_mps == 30.0


def test_an_unknown_variant_lists_the_known_ones():
    with pytest.raises(ConfigError, match="highway_4lane"):
        build_road("autobahn")


def test_a_missing_netconvert_is_a_clear_error(tmp_path):
    with pytest.raises(SumoError, match="netconvert"):
        build_road("highway_4lane", cache_dir=tmp_path, netconvert=str(tmp_path / "netconvert"))
