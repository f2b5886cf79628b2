"""d4sumo: adversarial driving maneuvers against ACC platoons, found by falsification on SUMO."""

__version__ = "0.21.0"
