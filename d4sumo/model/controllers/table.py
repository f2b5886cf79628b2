"""The [controller] table: which controller a follower runs, and its parameters, resolved and checked
(`control` for d4sumo's laws and the registry, `carfollowing` for SUMO's models, `fmu` for FMUs, `plugins` for
a user's class). `config.EpisodeConfig` holds one, or one per follower.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

from ...errors import ConfigError
from . import carfollowing
from .control import AS_RUN_DEFAULTS, resolve_controller, user_module
from .fmu import SHA_KEY, is_fmu
from .plugins import ControllerImportError, NotImported, build_params


@dataclass(frozen=True)
class ControllerConfig:
    """One follower's controller and its parameters (as (name, value) pairs, all resolved).

    ``cls`` is a Python controller ("switching", "timegap", "package.module:ClassName") or one of
    SUMO's car-following models ("sumo:ACC", "sumo:IDM", ...), whose parameters are SUMO's attributes
    for that model (see `carfollowing`).
    """

    cls: str = "switching"
    params: tuple[tuple[str, Any], ...] = ()
    where: str = dataclasses.field(default="controller", compare=False)  # its place in the config, for messages

    def __post_init__(self) -> None:
        if not isinstance(self.cls, str) or not self.cls:
            raise ConfigError(f"{self.where}.class", self.cls,
                              "a registered controller name, 'sumo:MODEL' or 'package.module:ClassName'")
        if carfollowing.is_sumo(self.cls):
            object.__setattr__(self, "params", carfollowing.check_params(self.cls, dict(self.params), self.where))
            return
        try:
            controller = resolve_controller(self.cls, self.params)
            resolved = build_params(controller, dict(self.params))  # validates every value
        except NotImported:  # read by name only: its parameters as given
            object.__setattr__(self, "params", tuple(self.params))
            return
        except ConfigError as exc:  # name the follower of a mixed platoon: controller.v2.acc_kp
            if self.where == "controller" or not exc.field.startswith("controller") or isinstance(exc, ControllerImportError):
                raise
            raise ConfigError(self.where + exc.field.removeprefix("controller"), exc.given, exc.allowed) from None
        object.__setattr__(self, "params", tuple(dataclasses.asdict(resolved).items()))

    @property
    def sumo_model(self) -> str | None:
        """The SUMO car-following model driving this follower, or None for a Python controller."""
        return carfollowing.model_of(self.cls) if carfollowing.is_sumo(self.cls) else None

    def controller_class(self) -> type:
        return resolve_controller(self.cls, self.params)

    def __getstate__(self) -> dict:
        """Pickled (to a worker, a warm-up's process) without its built parameters: a class made at run time (an
        FMU's) pickles by nothing but its name; they are built again where asked."""
        state = dict(self.__dict__)
        state.pop("_built", None)
        return state

    def build_params(self) -> Any:
        built = self.__dict__.get("_built")
        if built is None:
            built = build_params(self.controller_class(), dict(self.params))
            if dataclasses.is_dataclass(built) and type(built).__dataclass_params__.frozen:  # immutable: one for all who ask
                object.__setattr__(self, "_built", built)
        return built

    def to_dict(self) -> dict:
        """As a definition stores it: the authors' code's options only where they differ from the paper's
        text (`control.AS_RUN_DEFAULTS`), so campaigns stored before them keep their identity."""
        params = dict(self.params)
        if not self.sumo_model:
            params = {k: v for k, v in params.items() if not (k in AS_RUN_DEFAULTS and v == AS_RUN_DEFAULTS[k])}
        return {"class": self.cls, **params}

    @property
    def label(self) -> str:
        """A short name for reports: the class and the parameters that differ from its defaults."""
        if self.sumo_model:
            defaults = dict(carfollowing.check_params(self.cls, {}))
        elif is_fmu(self.cls):  # its content, not its defaults (which its file holds): a short hash
            sha = dict(self.params).get(SHA_KEY, "")
            return f"{self.cls}({sha[:8]})" if sha else self.cls
        elif user_module(self.cls) is None:
            defaults = dataclasses.asdict(self.controller_class().Params())
        else:  # a user's class is not imported for a name: every parameter is shown
            defaults = {}
        changed = [f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.params if defaults.get(k) != v]
        return self.cls + (f"({', '.join(changed)})" if changed else "")

    @classmethod
    def from_table(cls, table: Any, where: str = "controller") -> "ControllerConfig":
        """From a [controller] table, or a bare class name."""
        if isinstance(table, str):
            return cls(cls=table, where=where)
        if not isinstance(table, Mapping):
            raise ConfigError(where, table, "a table with a class key, or a controller name")
        values = dict(table)
        return cls(cls=values.pop("class", "switching"), params=tuple(values.items()), where=where)


def listens(controller: ControllerConfig) -> bool | None:
    """Whether a follower's controller reads V2V beacons (its class's ``listens``); None where a user's
    class may not be imported here (`plugins.names_only`: a stored definition says what it had)."""
    if controller.sumo_model:
        return carfollowing.listens(controller.sumo_model, dict(controller.params))
    try:
        return bool(getattr(controller.controller_class(), "listens", False))
    except NotImported:
        return None


def as_stored_ran(table: Any) -> Any:
    """A [controller] table as a campaign's definition stored it, with what its controller ran: the authors' code's
    options are left out where they hold the paper's value (`ControllerConfig.to_dict`), by name, for every Python
    controller. A class whose Params has such a key (a user's own, with its own default) gets the paper's value back,
    which it ran with; a switching controller's default is that value already. (Found in 0.21: such a campaign
    replayed with the class's default instead.)"""
    if not isinstance(table, Mapping):
        return table
    name = table.get("class", "switching")
    if not isinstance(name, str) or carfollowing.is_sumo(name) or is_fmu(name):
        return table
    try:
        fields = {f.name for f in dataclasses.fields(resolve_controller(name).Params)}
    except (ConfigError, TypeError):  # not importable here (names only, or not on this machine): as stored
        return table
    return {**table, **{k: v for k, v in AS_RUN_DEFAULTS.items() if k in fields and k not in table}}
