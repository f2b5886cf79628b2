"""Write the databases each earlier release of d4sumo wrote, for the test that holds their stored definitions and
identities (tests/search/test_releases.py): each version's first commit (its release) and the last that carried it
checked out beside this one, its own CLI run from there on a set of campaigns (those it knows; the others it
refuses, and are left out), each database two samples a campaign.

    python tools/earlier_databases.py                 # every release into tests/data/releases/
    python tools/earlier_databases.py --only 0.18.0 0.18.0-last   # some

Each database is written once: they are fixtures of what was, not of what is.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "tests" / "data" / "releases"
#: each version's first commit, its release (VERSION.sqlite), and the last that carried it (VERSION-last.sqlite): what a
#: database that says it was created by that version may hold, at both ends
FIRST = {
    "0.2.0": "930abcc22dc5abfe58d66e49cacd625bed241b62", "0.3.0": "54c2af860fa3a31ab40bd18617d726292961bcd5",
    "0.4.0": "c4ba4ae9834734db6f45ca8cd9979496555bcf20", "0.5.0": "c86c45f66841f2aafada13f5d6be4ffd4f3d6e2c",
    "0.6.0": "0a8e40fd9299879eca0cd4651aa439dbb69f8c4c", "0.7.0": "404d49e5bf4e6d31fdf70f0cc41da0be1d650c29",
    "0.8.0": "6a6b9c10ee868c37d633b80f48b40338a6fdf318", "0.9.0": "4cd3ed22028e85eba8449739a3288f7130097919",
    "0.10.0": "8a6226c9e54c12d298e38aa04dd6537c5ca69f29", "0.10.1": "3dc2125e6c66844a2575aae32a5ba0bb03d74eb0",
    "0.11.0": "5b02d69d3516848a86864cbf6bc7044d9c371a70", "0.12.0": "52db78c37f13c711f008a05ca455b559ead8b34c",
    "0.13.0": "e01e3cd5b14e25d1e3acad2b8ae6771c5e85102e", "0.14.0": "2c35b89875bbbf33ed3bc429c651cb8b0be2f57b",
    "0.15.0": "3d86346ee205782617d4568d4796d989bbf5e2ab", "0.16.0": "64cdbec81308488e9f56dd9591eaa7b93e42b86e",
    "0.17.0": "5979d9c61e25df0dfdad269722d41ed45480683c", "0.18.0": "4ebab9133cbe82cb49cf7ff5dc6092b09b3c465f",
    "0.19.0": "37209632f4299a699f48c386f3f1ce907ef47504", "0.20.0": "a1980e9e676e3ada94f375d5f2362b4957e506be",
}
LAST = {
    "0.2.0": "575b9ab161ce2e25794f19293d01a0304609cf07", "0.3.0": "1a081a1179b81bc50e6ad9c20bb3cafdce0a0d14",
    "0.4.0": "192538375e588948cac2a054aa87cfa4dff4ce55", "0.5.0": "a93446f5602295610be9a9aac36402056dc7d967",
    "0.6.0": "40224ef201983ea75c9a01339a2c3b1f82fe8771", "0.7.0": "54cf14cfc302a6d6c332cc1be29db8fc6ce950ac",
    "0.8.0": "05644c03f1f2917239026ecf6e80da5f286d3cfd", "0.9.0": "7ab178aad2d6aa1b350ccf2aed50da2d8f8ccf52",
    "0.10.0": "1f5837d09234506db6eca24dee2c103f96dae5a4", "0.10.1": "3112c61eb346955e4d7b19db6632c4c08d7d2db0",
    "0.11.0": "0e968c93052427896faf92e32e73689d0ab46554", "0.12.0": "d6fa59dab3b205dfb8b65d34b91547b044aada09",
    "0.13.0": "25441342a5d556a5ce8d6bee8bd244c826e47b1b", "0.14.0": "d15d095eb38468c4cefa03b52f4b3db49e2ee818",
    "0.15.0": "a7451d78651163edfc8d8c9ce496cd4fb52322f0", "0.16.0": "c58457c6e246ae5d6a00063245041cbc9843e1ad",
    "0.17.0": "cf21cc24106b047c784bd4554172484494ee9dbc", "0.18.0": "4f20e836f1a08f4985342dcb235b8fe4ebb3c67b",
    "0.19.0": "820a899a077175fa326843b1b96f10d65db5509b",  # as it landed (what followed at 0.19.0 was 0.20's work)
    "0.20.0": "55faf7e64ed5dc46906ca2802b287f527e8448cf",
}
RELEASES = {**{v: c for v, c in FIRST.items()}, **{f"{v}-last": c for v, c in LAST.items()}}
#: the campaigns, as falsify's flags (a road of one's own by its path from the checkout's root, stored so: a test reads it from
#: this checkout's root)
CAMPAIGNS = {
    "default": [],
    "steady": ["--start", "steady", "--setpoint", "5"],
    "bo": ["--optimizer", "bo"],
    "ce": ["--optimizer", "ce"],
    "random": ["--optimizer", "random"],
    "turbo": ["--optimizer", "turbo"],
    "auto": ["--optimizer", "auto"],
    "spline": ["--attack", "spline", "--optimizer", "random"],
    "timegap": ["--controller", "timegap", "--start", "steady"],
    "sumo_acc": ["--controller", "sumo:ACC", "--start", "steady", "--optimizer", "random"],
    "radar": ["--start", "steady", "--set", "radar.gap_noise_m=0.5", "--optimizer", "random"],
    "cacc": ["--controller", "cacc", "--start", "steady", "--setpoint", "5", "--optimizer", "random"],
    "lie": ["--controller", "cacc", "--start", "steady", "--setpoint", "5", "--set", "attack.message=offset",
            "--set", "attack.message_field=speed", "--optimizer", "random"],
    "traffic": ["--start", "steady", "--set", "traffic.vehicles_per_hour=600", "--optimizer", "random"],
    "cutin": ["--maneuver", "cutin", "--start", "steady", "--optimizer", "random"],
    "swerve": ["--maneuver", "swerve", "--start", "steady", "--optimizer", "random", "--duration", "20"],
    "own_road": ["--network", "examples/roads/three_edges", "--start", "steady", "--optimizer", "random"],
    "cacc_traffic": ["--controller", "cacc", "--start", "steady", "--setpoint", "5", "--set", "traffic.vehicles_per_hour=600",
                     "--optimizer", "random"],
    "cacc_cutin": ["--controller", "cacc", "--maneuver", "cutin", "--start", "steady", "--optimizer", "random"],
}


def release_tree(commit: str, folder: Path) -> Path:
    """The release's files, checked out into ``folder`` (no work of this checkout touched)."""
    tree = folder / commit[:10]
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), commit], check=True,
                   capture_output=True)
    return tree


def write(version: str, commit: str, folder: Path) -> None:
    out = OUT / f"{version}.sqlite"
    if out.exists():
        print(f"{version}: {out.relative_to(ROOT)} is there already (a fixture of what was): left as it is")
        return
    tree = release_tree(commit, folder)
    try:
        part = folder / f"{version}.sqlite"
        env = {**os.environ, "PYTHONPATH": str(tree)}
        for name, flags in CAMPAIGNS.items():
            argv = [sys.executable, "-m", "d4sumo.cli", "falsify", "--duration", "10", "--samples", "2", "--seed", "1",
                    *(f.replace("{tree}", str(tree)) for f in flags), "--db", str(part), "--quiet"]
            done = subprocess.run(argv, cwd=tree, env=env, capture_output=True, text=True, timeout=600)
            said = (done.stderr.strip().splitlines() or [""])[-1]
            print(f"{version} {name}: {'stored' if done.returncode == 0 else 'left out (' + said[:100] + ')'}")
        OUT.mkdir(parents=True, exist_ok=True)
        os.replace(part, out)
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", metavar="VERSION", help="these releases (default: all)")
    args = parser.parse_args()
    chosen = args.only or list(RELEASES)
    unknown = [v for v in chosen if v not in RELEASES]
    if unknown:
        print(f"earlier_databases: --only: got {', '.join(unknown)}; allowed: {', '.join(RELEASES)}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="d4sumo-releases-") as folder:
        for version in chosen:
            write(version, RELEASES[version], Path(folder))
    return 0


if __name__ == "__main__":
    sys.exit(main())
