"""A user's own controller class, named package.module:ClassName: what is said when it cannot be had."""

from __future__ import annotations

import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.controllers.plugins import import_controller, names_only


def test_a_module_that_imports_without_the_class_says_so_and_names_its_classes(tmp_path, monkeypatch):
    """Regression: `--controller mymodule:Missing` said "mymodule did not import here" of a module that imported."""
    import uuid

    name = f"ctl_{uuid.uuid4().hex[:8]}"  # a module of its own: Python caches what it imported
    (tmp_path / f"{name}.py").write_text("class Gentle:\n    pass\n\n\nclass Firm:\n    pass\n\n\ndef helper():\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError) as info:
        import_controller(f"{name}:Missing")
    assert str(info.value) == (f"controller.class: got '{name}:Missing'; allowed: a class of {name}; {name} imported "
                               f"({tmp_path / name}.py) but has no class Missing (its classes: Firm, Gentle)")


def test_within_names_only_a_users_controller_is_never_imported(tmp_path, monkeypatch):
    """Reading a database someone sent must never run its code."""
    import uuid

    name = f"ctl_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(f"open({str(tmp_path / 'ran')!r}, 'w').close()\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with names_only(), pytest.raises(ConfigError, match="read by its name only"):
        import_controller(f"{name}:X")
    assert not (tmp_path / "ran").exists()


def test_a_users_subclass_of_a_cooperative_law_answers_observe_only_and_is_taken(tmp_path, monkeypatch):
    """The cooperative laws answer observe() only (they no longer carry a command() that raised): a user's subclass of
    one is a controller all the same, and one with neither method is refused in one line."""
    import uuid

    name = f"ctl_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(
        "from d4sumo.model.controllers.control import PathCACC\n\n\nclass Mine(PathCACC):\n    pass\n\n\n"
        "from dataclasses import dataclass\n\n\nclass Mute:\n    @dataclass\n    class Params:\n        pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    from d4sumo.model.controllers.control import PathCACC

    assert issubclass(import_controller(f"{name}:Mine"), PathCACC) and not hasattr(PathCACC, "command")
    with pytest.raises(ConfigError, match=r"an observe\(\) method \(or command\(\) on three floats\)"):
        import_controller(f"{name}:Mute")
