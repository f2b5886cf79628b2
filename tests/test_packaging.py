"""The built wheel works anywhere: installed into a fresh environment, run from an unrelated folder."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from conftest import NATIVE_CALLS_EXPECTED, made_ahead, side_by_side

ROOT = Path(__file__).resolve().parent.parent


@made_ahead()
def wheel(tmp_path_factory):
    """The project's wheel, built from a copy of its files (the checkout stays clean)."""
    src = tmp_path_factory.mktemp("src")
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True, text=True)
    names = files.stdout.split() if files.returncode == 0 else []
    if not names:  # not a git checkout: copy the package's own folders
        names = [str(p.relative_to(ROOT)) for d in ("d4sumo", "sumo_scenarios") for p in (ROOT / d).rglob("*") if p.is_file()]
        names += ["pyproject.toml", "README.md"]
    for name in names:
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    out = tmp_path_factory.mktemp("dist")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(src)],
                           capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stderr
    (whl,) = out.glob("d4sumo-*.whl")
    return whl


def test_the_wheel_ships_every_scenario_variant(wheel):
    """pyproject.toml lists the packages one by one (the variants are mapped into d4sumo): none may be missing."""
    names = zipfile.ZipFile(wheel).namelist()
    for variant in (p.name for p in (ROOT / "sumo_scenarios").iterdir() if p.is_dir() and not p.name.startswith("_")):
        for data in ("highway.nod.xml", "highway.edg.xml", "README.md"):
            assert f"d4sumo/sumo_scenarios/{variant}/{data}" in names
    # Regression: the variants were installed as a top-level package of their own, `sumo_scenarios`.
    assert {n.split("/")[0] for n in names if not n.startswith("d4sumo-")} == {"d4sumo"}
    modules = {str(p.relative_to(ROOT)) for p in (ROOT / "d4sumo").rglob("*.py")}
    assert len(modules) > 30 and modules <= set(names)  # every module of every subpackage
    assert not any(n.startswith("tests/") for n in names)
    # the followers stepped in C (d4sumo.model.controllers.compiled), built for this platform
    assert [n for n in names if n.startswith("d4sumo/model/controllers/_followers.") and n.endswith(".so")], names
    # and libsumo's own C++ calls for the loop in C (d4sumo/engine/_sumo_calls.cpp), where a C++ compiler built them
    assert [n for n in names if n.startswith("d4sumo/engine/_sumo_calls.") and n.endswith(".so")] or not NATIVE_CALLS_EXPECTED, names


@pytest.mark.sumo
def test_the_installed_wheel_runs_an_episode_from_an_unrelated_folder(wheel, tmp_path):
    """Regression: a non-editable install had no scenario variants, so every episode exited 2."""
    env_dir = tmp_path / "env"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    python = env_dir / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    with zipfile.ZipFile(wheel) as z:  # what pip does with the wheel; the dependencies come from this environment
        z.extractall(site)
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "XDG_CACHE_HOME": str(tmp_path / "cache")}
    run = lambda *code: subprocess.run([str(python), *code], cwd=work, capture_output=True, text=True, env=env, timeout=300)
    # these four side by side: none reads what another writes
    where, listed, episode, built = side_by_side([
        lambda: run("-c", "import d4sumo.sumo_scenarios as s, d4sumo.model.controllers._followers as c; print(s.__file__, c.__file__)"),
        lambda: run("-m", "d4sumo.cli", "scenarios"),
        lambda: run("-m", "d4sumo.cli", "simulate", "--knots=-1,1,1,-1,1,-1,-1,1,-1", "--json"),
        lambda: run("-m", "d4sumo.cli", "build-fmu", "--fmi", "3", "--out", "acc.fmu"),  # its C sources ship in the wheel
    ])
    assert where.returncode == 0, where.stderr
    assert all(line.startswith(str(site)) for line in where.stdout.split()), where.stdout  # not the checkout
    native = run("-c", "import libsumo; from d4sumo.engine.calls import native_calls; print(native_calls(libsumo) is not None)")
    assert native.stdout.strip() == str(NATIVE_CALLS_EXPECTED), native.stderr  # the loop in C takes libsumo's own functions
    assert listed.returncode == 0 and "highway_3lane_120kmh" in listed.stdout, listed.stderr
    assert episode.returncode == 0, episode.stderr
    assert json.loads(episode.stdout)["outcome"] == "attacker_crash"
    assert built.returncode == 0, built.stderr
    episode = run("-m", "d4sumo.cli", "simulate", "--controller", "fmu:acc.fmu", "--knots=-1,1,1,-1,1,-1,-1,1,-1", "--json")
    assert episode.returncode == 0 and json.loads(episode.stdout)["outcome"] == "attacker_crash", episode.stderr


def test_toml_is_read_through_one_import_that_falls_back_on_python_3_10():
    """Regression: `import tomllib` (Python 3.11+) in three modules; on Python 3.10, which pyproject.toml
    allows, every command ended in ModuleNotFoundError. tomlfiles.py alone imports it, with tomli before 3.11."""
    importing = sorted(str(p.relative_to(ROOT)) for d in ("d4sumo", "tools") for p in (ROOT / d).rglob("*.py")
                       if "import tomllib" in p.read_text())
    assert importing == ["d4sumo/tomlfiles.py"]
    source = (ROOT / "d4sumo" / "tomlfiles.py").read_text()
    assert "if sys.version_info >= (3, 11):\n    import tomllib\nelse:" in source and "import tomli as tomllib" in source
    assert "tomli>=1.1; python_version < '3.11'" in (ROOT / "pyproject.toml").read_text()


def test_the_source_distribution_holds_every_file_the_extension_is_built_from(tmp_path):
    """Found by review: its headers were package data of a folder that is no package, which setuptools warned it
    would ignore. They are the extension's dependencies (setup.py) instead, which the sdist holds: an install
    from it without them would go on without the extension, at the Python's speed, and say nothing."""
    src = tmp_path / "src"
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True, text=True)
    if files.returncode != 0:
        pytest.skip("not a git checkout")
    for name in files.stdout.split():
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    build = subprocess.run([sys.executable, "setup.py", "-q", "sdist", "-d", str(tmp_path / "dist")], cwd=src,
                           capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stderr
    import tarfile

    (archive,) = (tmp_path / "dist").glob("d4sumo-*.tar.gz")
    names = {n.split("/", 1)[1] for n in tarfile.open(archive).getnames() if "/" in n}
    setup = (ROOT / "setup.py").read_text()
    needed = {"d4sumo/model/controllers/_followers.c", "d4sumo/engine/_sumo_calls.cpp",
              *(part for part in names if part.startswith("d4sumo/model/controllers/csrc/"))}
    assert {"d4sumo/model/controllers/csrc/followers.h", "d4sumo/model/controllers/csrc/laws.h", "d4sumo/model/controllers/csrc/channel.h",
            "d4sumo/model/controllers/csrc/column.h", "d4sumo/model/controllers/csrc/world_calls.h",
            "d4sumo/fmus/switching.h"} <= names and needed <= names
    assert all(f'"{part}"' in setup for part in needed if part.endswith(".h"))  # each a dependency of the build
