"""Output files written whole: the parts a killed writer left are removed by the next writer."""

from __future__ import annotations

import os
import subprocess
import sys

from d4sumo.files import part_of, remove_stale_parts


def test_a_killed_writers_parts_are_removed_and_a_live_writers_kept(tmp_path):
    """Regression: `kill -9` during replay --fcd or report left .NAME.PID.part files and folders beside the
    output, one more at every kill, and nothing ever removed them."""
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # a process id nobody holds now
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        target = tmp_path / "best.xml"
        (tmp_path / f".best.xml.{gone.pid}.part").write_text("cut short")
        (tmp_path / f".best.xml.{alive.pid}.part").write_text("being written")
        folder = tmp_path / f".report.{gone.pid}.part"
        folder.mkdir()
        (folder / "heatmaps.png").write_bytes(b"")
        (tmp_path / ".other.xml.1.part").write_text("another target's")
        remove_stale_parts(target)
        remove_stale_parts(tmp_path / "report")
        assert sorted(p.name for p in tmp_path.iterdir()) == [f".best.xml.{alive.pid}.part", ".other.xml.1.part"]
    finally:
        alive.kill()
        alive.wait()


def test_a_part_is_named_for_its_target_and_this_process(tmp_path):
    assert part_of(tmp_path / "s.csv") == tmp_path / f".s.csv.{os.getpid()}.part"
    (tmp_path / f".s.csv.{os.getpid()}.part").write_text("this process's own")
    remove_stale_parts(tmp_path / "s.csv")
    assert part_of(tmp_path / "s.csv").exists()
