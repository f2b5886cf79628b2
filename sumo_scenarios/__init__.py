"""The road network variants shipped with d4sumo: one folder each, plain SUMO node/edge XML.

Data only, installed as ``d4sumo.sumo_scenarios``; read through `d4sumo.engine.scenarios` (``d4sumo scenarios`` lists them).
"""
