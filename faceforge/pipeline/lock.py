"""An exclusive lock on a workdir (``fcntl.flock`` on ``<workdir>/.faceforge.lock``).

Two faceforge processes on the same workdir run one after the other; the second
says that it waits and for whom. The kernel drops the lock when its holder dies,
so a killed run never leaves the workdir locked.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import Callable

LOCK_NAME = ".faceforge.lock"


class WorkdirLock:
    """Context manager holding the workdir's lock; ``notify`` is told once if it must wait."""

    def __init__(self, workdir: str | Path, notify: Callable[[str], None] = lambda msg: None):
        self.path = Path(workdir) / LOCK_NAME
        self.notify = notify
        self._fd: int | None = None

    def __enter__(self) -> "WorkdirLock":
        from faceforge.exceptions import StageError

        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except IsADirectoryError:
            raise StageError("the workdir's lock file is a folder; remove it (faceforge writes a file there)",
                             self.path) from None
        except OSError as exc:
            raise StageError(f"cannot create the workdir's lock file: {exc.strerror or exc}", self.path) from None
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip() or "unknown"
                self.notify(f"waiting for another faceforge process (pid {holder}) working in {self.path.parent}")
                fcntl.flock(fd, fcntl.LOCK_EX)
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            try:
                os.ftruncate(self._fd, 0)
            finally:
                fcntl.flock(self._fd, fcntl.LOCK_UN)
                os.close(self._fd)
                self._fd = None
