"""One input document: config files, flags and sweep files checked by the same code. No SUMO."""

from __future__ import annotations

import re

import pytest

from d4sumo.errors import ConfigError
from d4sumo.inputs import attack_of, campaign_of, episode_config, read_document, with_overrides


def write(tmp_path, text, name="c.toml"):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def test_flags_win_over_the_file(tmp_path):
    doc = read_document(write(tmp_path, '[scenario]\nsetpoint_m = 9\nspeed_mps = 20\n[controller]\nacc_kp = 1.1\n'))
    c = episode_config(with_overrides(doc, {"scenario.setpoint_m": 3.0}))
    assert c.setpoint_m == 3.0 and c.speed_mps == 20 and dict(c.controller.params)["acc_kp"] == 1.1


def test_optimizer_options_come_from_search_tables(tmp_path):
    doc = read_document(write(tmp_path, '[search]\noptimizer = "ce"\nsamples = 50\n[search.ce]\nbatch_size = 25\n'))
    campaign = campaign_of(doc)
    assert campaign.optimizer == "ce" and campaign.samples == 50
    assert dict(campaign.optimizer_options)["batch_size"] == 25
    assert campaign.definition()["optimizer_options"]["batch_size"] == 25


@pytest.mark.parametrize(
    "text, field",
    [
        ("[scenaro]\nx = 1\n", "scenaro"),
        ("[scenario]\nsetpont_m = 3\n", "scenario.setpont_m"),
        ("[spec]\nd_saf_m = 1\n", "spec.d_saf_m"),
        ("[search]\nsample = 3\n", "search.sample"),
        ("[attack]\nfamilly = 'sine'\n", "attack.familly"),
        ("[search.ce]\nbatchsize = 3\n", "search.ce.batchsize"),
        ("[search]\nce = 3\n", "search.ce"),
        ("scenario = 5\n", "[scenario]"),
        ("[controller]\nacc_kp = inf\n", "controller.acc_kp"),
        ("[controller]\nacc_kp = nan\n", "controller.acc_kp"),
        ("[controller]\nacc_kp = 'high'\n", "controller.acc_kp"),
        ("[controller]\nclass = 5\n", "controller.class"),
        ("[vehicle]\nlength_m = inf\n", "vehicle.length_m"),
        ("[scenario]\nsetpoint_m = '7'\n", "scenario.setpoint_m"),
        ("[scenario]\nfollowers = 3.0\n", "scenario.followers"),
        ("[scenario]\nstart = ['rest']\n", "scenario.start"),
        ("[scenario]\nnetwork = 4\n", "scenario.network"),
        ("[search]\nsamples = '100'\n", "search.samples"),
        ("[search]\nseed = 1.5\n", "search.seed"),
        ("[search]\noptimizer = ['bo']\n", "search.optimizer"),
        ("[attack]\nfamily = 7\n", "attack.family"),
        ("[attack]\ndelta_s = nan\n", "attack.delta_s"),
        ("[spec]\nformula = 3\n", "spec.formula"),
        ("[spec]\nd_safe_m = inf\n", "spec.d_safe_m"),
        ("[attack]\nparams = [0.1]\n", "attack.params"),
    ],
)
def test_a_bad_config_file_names_the_field(tmp_path, text, field):
    with pytest.raises(ConfigError) as info:
        campaign_of(read_document(write(tmp_path, text)))
    assert field in info.value.field


def test_a_file_that_is_not_utf8_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="UTF-8"):
        read_document(write(tmp_path, b"[scenario]\nnetwork = '\xff\xfe'\n"))


def test_malformed_toml_says_where(tmp_path):
    with pytest.raises(ConfigError, match="valid TOML"):
        read_document(write(tmp_path, "[scenario]\nsetpoint_m = = 3\n"))


@pytest.mark.parametrize(
    "attack, field",
    [
        ({"params": [0.1]}, "attack.params"),
        ({"family": "sine"}, "attack.params"),
        ({"family": "sine", "params": "x"}, "attack.params"),
        ({"family": "sine", "params": [0.1, "a", 2]}, "attack.params"),
        ({"family": "sine", "params": [0.1, 0.2]}, "attack.params"),
        ({"family": "zigzag", "params": [0.1]}, "attack.family"),
    ],
)
def test_a_bad_attack_of_an_episode_names_the_field(attack, field):
    with pytest.raises(ConfigError) as info:
        attack_of({"attack": attack})
    assert info.value.field.startswith(field)


def test_a_knot_attack_of_an_episode():
    family, params = attack_of({"attack": {"family": "knots", "params": [0, 1, -1], "horizon_s": 12}})
    assert family.name == "knots" and list(params) == [0, 1, -1]


def test_controller_flags_reach_one_follower_of_a_mixed_platoon():
    doc = with_overrides({"controller": ["sumo:ACC", "switching", "sumo:IDM"]}, {"controller.v1.tau": 0.8, "controller.v2.acc_kp": 1.2})
    config = episode_config(doc)
    assert dict(config.controllers[0].params)["tau"] == 0.8 and dict(config.controllers[1].params)["acc_kp"] == 1.2
    with pytest.raises(ConfigError, match="controller.VEHICLE.KEY"):
        with_overrides(doc, {"controller.tau": 1.0})
    # a whole [controller] at once (a sweep grid's controller axis): a name, a table or a list
    assert episode_config(with_overrides(doc, {"controller": "timegap"})).controller.cls == "timegap"
    assert episode_config(with_overrides({}, {"controller": {"class": "sumo:ACC", "tau": 0.5}})).controller.label == "sumo:ACC(tau=0.5)"


def test_the_paper_as_run_preset_lays_the_authors_options_under_the_document_and_maps_the_family():
    from d4sumo.inputs import campaign_of

    c = campaign_of({"preset": "paper-as-run", "attack": {"family": "persistent"}, "scenario": {"setpoint_m": 2.0}})
    assert c.attack == "persistent-coded" and c.d_safe_m == 0.05
    cfg = c.config
    assert (cfg.start, cfg.speed_mps, cfg.duration_s, cfg.attacker_cruise_offset_mps, cfg.end_distance_m, cfg.setpoint_m) == \
        ("rest", 20.0, 25.0, -5.0, 760.0, 2.0)
    params = dict(cfg.controller.params)
    assert (params["switching_rule"], params["low_level"], params["low_kp"], params["control_period_s"]) == ("code", "pid", 0.1, 0.1)
    # the document's own values win; knots take the HEAD's low-level gains
    k = campaign_of({"preset": "paper-as-run", "scenario": {"speed_mps": 30.0, "start": "steady"}})
    assert k.attack == "knots-coded" and k.config.speed_mps == 30.0 and k.config.start == "steady"
    assert dict(k.config.controller.params)["low_ki"] == 0.35 and k.config.attacker_cruise_offset_mps == 0.0
    # stored resolved: the definition holds the options, not the preset's name
    assert "preset" not in str(k.definition()) and k.definition()["config"]["controller"]["low_level"] == "pid"


@pytest.mark.parametrize("controller", ["sumo:IDM", "timegap", ["switching", "timegap", "sumo:IDM"]])
def test_the_paper_as_run_preset_sets_the_code_controllers_options_on_the_papers_controller_only(controller):
    """Regression: the preset laid the paper's controller options (switching_rule, ...) on any follower, so
    --preset paper-as-run with a SUMO model or the time-gap ACC was refused, naming switching_rule."""
    c = campaign_of({"preset": "paper-as-run", "controller": controller})
    followers = c.config.controllers if isinstance(controller, list) else [c.config.controller]
    for follower in followers:
        params = dict(follower.params)
        assert (params.get("switching_rule") == "code") == (follower.cls == "switching")
    assert c.attack == "knots-coded" and c.config.collision_gap_m == 0.05


@pytest.mark.parametrize("doc, message", [
    ({"preset": "paper"}, "preset: got 'paper'; allowed: one of paper-as-run"),
    ({"preset": "paper-as-run", "attack": {"family": "sine"}}, "attack.family: got 'sine'; allowed: one of persistent, intermittent, knots"),
])
def test_a_bad_preset_is_one_line(doc, message):
    from d4sumo.inputs import campaign_of

    with pytest.raises(ConfigError, match=re.escape(message)):
        campaign_of(doc)


def test_the_papers_psi_and_the_collisions_draw_their_line_at_one_distance():
    """Found in review: collision_gap_m 1.5 with d_safe 0 stored successes whose robustness was negative.
    One given sets the other; both given and different is refused; a formula of one's own leaves both."""
    from d4sumo.inputs import campaign_of

    c = campaign_of({"spec": {"d_safe_m": 0.3}})
    assert c.d_safe_m == c.config.collision_gap_m == 0.3
    c = campaign_of({"scenario": {"collision_gap_m": 1.5}})
    assert c.d_safe_m == c.config.collision_gap_m == 1.5
    with pytest.raises(ConfigError) as info:
        campaign_of({"scenario": {"collision_gap_m": 1.5}, "spec": {"d_safe_m": 0.0}})
    assert info.value.field == "spec.d_safe_m"
    c = campaign_of({"scenario": {"collision_gap_m": 1.5}, "spec": {"formula": "always(gap_1 > 0)"}})
    assert c.d_safe_m == 0.0 and c.config.collision_gap_m == 1.5
    preset = campaign_of({"preset": "paper-as-run", "attack": {"family": "persistent"}, "spec": {"d_safe_m": 0.0}})
    assert preset.d_safe_m == preset.config.collision_gap_m == 0.0  # what the document sets wins over the preset
