"""Opening the files the trials read (study files' clips, the database):
regular files only.

A study names its videos and ground truth, and a FIFO or a device among them
must be refused, not waited on or read without end: ``open_regular`` checks
the descriptor it opened (not the name before opening it, which could change
in between). Nothing here knows what the files hold.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import IO

from cosim.errors import ConfigError


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, for a message ("a FIFO", ...)."""
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a device"),
                       (stat.S_ISBLK, "a device"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return name
    return "not a regular file"


def open_regular(p: Path) -> IO[bytes]:
    """``p`` opened for reading if it is a regular file; ``ConfigError`` if it
    is anything else (a FIFO, a device, a folder: never waited on or read).
    The check is made on the file opened, not on the name before opening it."""
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise ConfigError(f"{p}: cannot open it: {e.strerror or e}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise ConfigError(f"{p}: it is {file_kind(mode)}, not a regular file")
    return os.fdopen(fd, "rb")
