"""Control laws of one file each: a follower controller class with a ``law_name``, found here and
registered under it (`control.register_controller`), so that adding a law is its file, its test and its
row in docs/systems-under-test.md (docs/contributing.md).

A law here is pure code, no SUMO, and follows the one contract (`control.FollowerController`): a
``Params`` dataclass, the constructor every controller has, and ``observe(observation) -> u``. It runs in
Python wherever it plays (alone, in a batch, among traffic); only the paper's and the cooperative laws
also have a compiled form (`compiled`), checked against their Python bit for bit.
"""

from __future__ import annotations

import importlib
import pkgutil

#: every law of this package by its name, in the order of their files
LAWS: dict[str, type] = {}

for _info in sorted(pkgutil.iter_modules(__path__), key=lambda info: info.name):
    _module = importlib.import_module(f"{__name__}.{_info.name}")
    for _cls in vars(_module).values():
        if isinstance(_cls, type) and _cls.__module__ == _module.__name__ and getattr(_cls, "law_name", None):
            if _cls.law_name in LAWS:
                raise ValueError(f"two laws are named {_cls.law_name!r}: {LAWS[_cls.law_name].__module__} and {_module.__name__}")
            LAWS[_cls.law_name] = _cls
