"""What --network names: shipped variants, folders, network files; and what is said of a name that is none."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from d4sumo.engine.networks import network_source
from d4sumo.errors import ConfigError


@pytest.mark.parametrize("given, allowed", [
    ("nosuch.net.xml", "a *.net.xml that exists (there is no {cwd}/nosuch.net.xml)"),
    ("{tmp}/two_edges/road.nod.xml", "the folder that holds the node and edge files ({tmp}/two_edges), not one of them"),
    ("{tmp}/two_edges/notes.txt", "one of highway_1lane, highway_3lane_120kmh, highway_4lane, a folder with *.nod.xml and "
                                  "*.edg.xml, or a *.net.xml (notes.txt is not one: a network file's name ends in .net.xml)"),
    ("{tmp}/two_edges/map.osm", "a network file (*.net.xml): import an OpenStreetMap file with netconvert first: "
                                "netconvert --osm-files {tmp}/two_edges/map.osm -o map.net.xml"),
    ("{tmp}/nosuch.osm", "an OpenStreetMap file that exists, imported with netconvert first (there is no {tmp}/nosuch.osm)"),
    ("{tmp}", "a folder with exactly one *.nod.xml and one *.edg.xml, or one *.net.xml (it holds 0 *.nod.xml, 0 *.edg.xml, "
              "0 *.net.xml)"),
], ids=["missing network file", "a node file", "another file", "an OSM file", "a missing OSM file", "a folder of none"])
def test_a_network_that_is_none_says_what_is_wrong_with_the_path_given(tmp_path, monkeypatch, given, allowed):
    """Regression: a missing *.net.xml and an OSM file were told only the list of what --network takes."""
    monkeypatch.chdir(tmp_path)
    shutil.copytree(Path(__file__).resolve().parents[2] / "examples" / "roads" / "two_edges", tmp_path / "two_edges")
    (tmp_path / "two_edges" / "notes.txt").write_text("notes")
    (tmp_path / "two_edges" / "map.osm").write_text("<osm/>")
    given, allowed = given.format(tmp=tmp_path), allowed.format(tmp=tmp_path, cwd=tmp_path)
    with pytest.raises(ConfigError) as info:
        network_source(given)
    assert str(info.value) == f"scenario.network: got {given!r}; allowed: {allowed}"
