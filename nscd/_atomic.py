"""Crash-safe file writes: after a kill or a power cut a file holds its old content or its new one.

A whole file is written to a temporary file in the same folder (same file system, so the
rename is atomic), flushed and ``fsync``-ed, then renamed over the target with
:func:`os.replace`; the folder is ``fsync``-ed so the rename itself is durable. A file that
grows line by line (a sweep's CSV) is appended with one ``write`` per line and ``fsync``-ed;
its reader must still refuse a line cut by a crash (see :mod:`nscd.sweep`).
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["append_line", "check_writable", "replacing", "write_text"]

# The process umask, read once (os.umask can only be read by setting it): the temporary file
# gets the permissions a plain open() would have given the target.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def _fsync_folder(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # some platforms (Windows) cannot open a folder; the rename is still atomic
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` atomically.

    The temporary file is in the folder of ``path`` and ends with the same suffix (writers
    that choose the format by extension, such as meshio, still work). If the block raises,
    or the process is interrupted, the temporary file is removed and ``path`` is untouched.

    Examples
    --------
    >>> with replacing("run.npz") as tmp:
    ...     np.savez_compressed(tmp, x=x)
    """
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp" + path.suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_UMASK)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def append_line(path: str | os.PathLike, line: str) -> None:
    """Append ``line`` (ending in a newline) to ``path`` (created if missing) with one write, then ``fsync``.

    Several processes may append to one file: each line goes in one ``O_APPEND`` write.
    """
    data = line.encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        written = os.write(fd, data)
        while written < len(data):  # a regular file takes it in one write; a pipe might not
            written += os.write(fd, data[written:])
        os.fsync(fd)
    finally:
        os.close(fd)


def check_writable(path: str | os.PathLike, name: str, create_folder: bool = True) -> Path:
    """Check, before any work, that a file can be written at ``path``.

    Parameters
    ----------
    path : path-like
    name : str
        The parameter that gave ``path``, for the error message.
    create_folder : bool
        Create the missing folders of ``path`` (else a missing folder is an error).

    Raises
    ------
    ValueError
        Naming the parameter ``name``, the path and the operating system's reason.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{name} == {str(path)!r} is a folder, must be a file path.")
    if not create_folder and not path.parent.is_dir():
        raise ValueError(f"{name} == {str(path)!r}: the folder {str(path.parent)!r} does not exist.")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".probe")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"{name} == {str(path)!r} cannot be written: {exc.strerror or exc} "
                         f"({exc.filename or path.parent}).") from None
    return path
