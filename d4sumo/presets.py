"""Presets: named bundles of options laid under an input document (`preset = "paper-as-run"` in a config
or sweep file, `--preset` on the command line). What the document itself sets wins; a campaign stores
the options resolved, so it never depends on what a preset means in a later version.

``paper-as-run`` is the paper as its authors' code ran it (the paper's tables came from that code,
which differs from its text; `SwitchingParams` and the ``*-coded`` attack families say how): their
switching rule, cruise PID and low-level PID, a 0.1 s control period and no pedal at the first call;
starts from rest; the attack families as coded; their episode lengths (25 s for the persistent attack;
the intermittent and knot files' 40 s limit sits inside a string literal, so they ran to VerifAI's
1,000 steps, 100 s) and end at 760 m; their scoring
distance (5 m between centres of 4.95 m cars: a 0.05 m bumper gap), which is also where their code
counts a crash (an attacker within it is an attacker crash): `scenario.collision_gap_m`. With ``--attack persistent`` or
``intermittent`` (their parametric scenarios, commit d458f6c) the followers' target speed is 20 m/s and
the attacker cruises 5 m/s slower until it attacks; with ``knots`` (their HEAD) the attack plays from
the first step and the low-level gains are HEAD's.
"""

from __future__ import annotations

import copy
from typing import Any, Mapping

from .errors import ConfigError

#: the authors' follower controller at commit d458f6c (the parametric attacks)
_CODE_CONTROLLER = {"switching_rule": "code", "cruise_pid": "code", "low_level": "pid", "control_period_s": 0.1,
                    "first_command_zero": True, "low_kp": 0.1, "low_ki": 0.1, "low_kd": 0.005}
_COMMON = {"scenario": {"start": "rest", "end_distance_m": 760.0, "collision_gap_m": 0.05}, "spec": {"d_safe_m": 0.05}}
#: per attack family named: the family as coded and what its scenario files set
PAPER_AS_RUN = {
    "persistent": {"attack": {"family": "persistent-coded"}, "controller": _CODE_CONTROLLER,
                   "scenario": {"speed_mps": 20.0, "duration_s": 25.0, "attacker_cruise_offset_mps": -5.0}},
    "intermittent": {"attack": {"family": "intermittent-coded"}, "controller": _CODE_CONTROLLER,
                     "scenario": {"speed_mps": 20.0, "duration_s": 100.0, "attacker_cruise_offset_mps": -5.0}},
    "knots": {"attack": {"family": "knots-coded"}, "controller": {**_CODE_CONTROLLER, "low_kp": 0.06, "low_ki": 0.35, "low_kd": 0.006},
              "scenario": {"duration_s": 100.0}},
}
PRESETS = ("paper-as-run",)


def apply_preset(doc: Mapping[str, Any], *, campaign: bool = False) -> dict:
    """The document with its preset's options laid under it (the document's own values win), its attack
    family mapped to the family as coded; a document without a preset, unchanged. ``campaign``: a
    campaign's document, whose family is knots when it names none (an episode without one has no attack,
    in the knot attack's scenario)."""
    doc = copy.deepcopy(dict(doc))
    name = doc.pop("preset", None)
    if name is None:
        return doc
    if name not in PRESETS:
        raise ConfigError("preset", name, f"one of {', '.join(PRESETS)}")
    named = doc.get("attack", {}).get("family")
    family = named or "knots"
    if family not in PAPER_AS_RUN:
        coded = tuple(f"{f}-coded" for f in PAPER_AS_RUN)
        if family in coded:  # named as coded already
            family = family.removesuffix("-coded")
        else:
            raise ConfigError("attack.family", family, f"one of {', '.join(PAPER_AS_RUN)} with preset {name} "
                                                       "(the families the authors' code played)")
    layers = {**_COMMON}
    for table, values in PAPER_AS_RUN[family].items():
        layers[table] = {**layers.get(table, {}), **values}
    for table, values in layers.items():
        if table == "controller":  # the code's controller options are the paper's controller's: its followers only
            mine = doc.get("controller", {})
            tables = [t if isinstance(t, Mapping) else {"class": t} for t in (mine if isinstance(mine, list) else [mine])]
            tables = [{**values, **t} if t.get("class", "switching") == "switching" else t for t in tables]
            doc["controller"] = tables if isinstance(mine, list) else tables[0]
            continue
        doc[table] = {**values, **doc.get(table, {})}
    if named or campaign:
        doc["attack"]["family"] = PAPER_AS_RUN[family]["attack"]["family"]  # the family as coded, whatever was named
    else:
        doc["attack"].pop("family")  # no attack: the attacker cruises
        if not doc["attack"]:
            doc.pop("attack")
    return doc
