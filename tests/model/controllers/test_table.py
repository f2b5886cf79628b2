"""A follower's controller table (`controllers.table.ControllerConfig`): its parameters built once, and the table
pickled without them (to workers and a warm-up's process)."""

from __future__ import annotations

import dataclasses
import pickle
import sys

from d4sumo.model.controllers.control import SwitchingController
from d4sumo.model.controllers.table import ControllerConfig


class Dynamic(SwitchingController):
    """A controller whose Params class is made at run time (as an FMU's is): it pickles by nothing but its name."""

    Params = dataclasses.make_dataclass("Params", [("acc_kp", float, dataclasses.field(default=0.5))], frozen=True,
                                        bases=(SwitchingController.Params,))


def test_built_parameters_are_kept_and_a_table_pickles_without_them():
    sys.modules[__name__].Dynamic = Dynamic
    table = ControllerConfig(f"{__name__}:Dynamic", (("acc_kp", 0.7),))
    built = table.build_params()
    assert table.build_params() is built and built.acc_kp == 0.7  # built once: frozen, one for all who ask
    again = pickle.loads(pickle.dumps(table))  # regression: the kept Params of a class made at run time broke pickling
    assert again == table and "_built" not in again.__dict__ and again.build_params() == built
