"""The road network variants shipped with d4sumo: one folder each, plain SUMO node/edge XML.

Data only; read through `d4sumo.scenarios` (``d4sumo scenarios`` lists them).
"""
