"""Files: a file's content hash, read once a version of it (`file_sha256`), and output files written whole:
each is written beside its target as a hidden part named with the writer's process id (``.NAME.PID.part``),
then renamed in. A part that a killed writer left behind (``kill -9`` leaves it no way out) is removed by the
next writer of the same target."""

from __future__ import annotations

import functools
import glob
import hashlib
import os
import shutil
from pathlib import Path


def part_of(target: Path) -> Path:
    """Where this process writes ``target`` (a file, or a folder) before renaming it in."""
    return target.with_name(f".{target.name}.{os.getpid()}.part")


def remove_stale_parts(target: Path) -> None:
    """The parts of ``target`` whose writer is gone: removed (a live writer's are left alone)."""
    for part in target.parent.glob(f".{glob.escape(target.name)}.*.part"):
        pid = part.name[len(target.name) + 2:-len(".part")]
        if pid.isdigit() and not _alive(int(pid)):
            if part.is_dir() and not part.is_symlink():
                shutil.rmtree(part, ignore_errors=True)
            else:
                part.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    if os.name != "posix":  # no cheap check elsewhere: keep the part
        return True
    try:
        os.kill(pid, 0)  # signal 0: only whether the process exists
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def file_sha256(path: Path) -> str:
    """The file's content hash, read once a version of it (an FMU of megabytes is named every episode)."""
    stat = os.stat(path)
    return _sha256(str(Path(path).resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=64)
def _sha256(path: str, mtime_ns: int, size: int) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
