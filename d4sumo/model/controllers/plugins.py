"""A user's own follower controller, named "package.module:ClassName": imported as Python's ``-m`` would
find it (installed, on PYTHONPATH, or in the current folder), never where nothing may be imported
(`names_only`: reading a database someone sent); and any controller's Params built from a config table.

Every way it can fail is one line naming controller.class: the module does not import here, it
imports without the class, the class is no controller. (The registered names, "switching" and
"timegap", are `control`'s.)
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import importlib
import os
import sys
from typing import Any, Callable, Mapping

from ...errors import ConfigError

#: Whether a user's controller module may be imported here. Reading a results database someone sent
#: must never run code: its readers name controllers without importing them (`names_only`).
_IMPORTS = contextvars.ContextVar("d4sumo_controller_imports", default=True)


class NotImported(ConfigError):
    """A user's controller named where nothing may be imported (`names_only`)."""


class ControllerImportError(ConfigError):
    """A user's controller class that cannot be had here: its module does not import (says how to make
    it importable), or it imports without the class (says which classes it has)."""

    def __init__(self, name: str, allowed: str, hint: str):
        self.hint = hint
        super().__init__("controller.class", name, f"{allowed}; {hint}")

    @classmethod
    def no_module(cls, name: str, reason: Exception) -> "ControllerImportError":
        module = name.partition(":")[0]
        return cls(name, "an importable 'package.module:ClassName'",
                   f"{module} did not import here ({reason}): run from the folder that holds "
                   f"{module.replace('.', '/')}.py, or put its folder on PYTHONPATH")

    @classmethod
    def no_class(cls, name: str, module: Any) -> "ControllerImportError":
        module_name, _, attr = name.partition(":")
        classes = sorted(k for k, v in vars(module).items()
                         if isinstance(v, type) and v.__module__ == module.__name__ and not k.startswith("_"))
        where = getattr(module, "__file__", None) or module_name
        has = f"its classes: {', '.join(classes[:12])}{', ...' if len(classes) > 12 else ''}" if classes else "it defines no class"
        return cls(name, f"a class of {module_name}", f"{module_name} imported ({where}) but has no class {attr} ({has})")


@contextlib.contextmanager
def names_only():
    """Within it, a user's controller ("package.module:ClassName") is a name: nothing is imported, its
    parameters are taken as stored, unchecked."""
    token = _IMPORTS.set(False)
    try:
        yield
    finally:
        _IMPORTS.reset(token)


def may_import() -> bool:
    """Whether a user's code (a module, an FMU) may be loaded here: not within `names_only`."""
    return _IMPORTS.get()


def import_controller(name: str) -> type:
    """The class a user's "package.module:ClassName" names, checked to be a controller (a Params
    dataclass and an observe method, or a command method on three floats: `observer`)."""
    if not _IMPORTS.get():
        raise NotImported("controller.class", name, "a controller read by its name only (nothing is imported here)")
    module_name, _, attr = name.partition(":")
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:  # the `d4sumo` script does not see the current folder
        sys.path.append(cwd)
    try:
        module = importlib.import_module(module_name)
    except (ImportError, ValueError) as exc:
        raise ControllerImportError.no_module(name, exc) from None
    except Exception as exc:  # found, but the module itself fails: a syntax error, an error raised at import
        raise ConfigError("controller.class", name, f"a module that imports without error ({module_name} raised "
                          f"{type(exc).__name__}: {exc})") from None
    cls = getattr(module, attr, None)
    if cls is None:
        raise ControllerImportError.no_class(name, module)
    params = getattr(cls, "Params", None)
    answers = callable(getattr(cls, "command", None)) or callable(getattr(cls, "observe", None))
    if not (isinstance(params, type) and dataclasses.is_dataclass(params)) or not answers:
        raise ConfigError("controller.class", name, "a class with a Params dataclass and an observe() method (or command() on three floats)")
    return cls


def observer(controller: Any) -> Callable[[Any], float]:
    """What the step loop calls for a follower's command: its controller's ``observe(observation)``, the one
    contract (`sensing.Observation`). A class written to the three-float form, ``command(gap_m, speed_mps,
    lead_speed_mps)`` (what its radar measured), is given those three of the observation: the one adapter."""
    observe = getattr(controller, "observe", None)
    if callable(observe):
        return observe
    command = controller.command
    return lambda o: command(o.gap_m, o.speed_mps, o.lead_speed_mps)


def build_params(cls: type, values: Mapping[str, Any]) -> Any:
    """The controller's Params from a config table, refusing keys the class does not know."""
    known = {f.name for f in dataclasses.fields(cls.Params)}
    for key in values:
        if key not in known:
            raise ConfigError(f"controller.{key}", values[key], f"a key of {', '.join(sorted(known))}")
    try:
        return cls.Params(**values)
    except ConfigError:  # a check of ours, naming its field
        raise
    except Exception as exc:  # a user's Params may check its values itself
        raise ConfigError("controller", dict(values), str(exc) if isinstance(exc, TypeError) else f"parameters its Params "
                          f"accepts ({type(exc).__name__}: {exc})") from None
