"""Atomic file and folder writes (the one place saucerfab writes output), hashing, the umask.

Outputs are written under a temporary name in the destination folder and
renamed into place once complete, so a crash or Ctrl-C never leaves a
half-written file or folder behind. ``os.replace`` is atomic on POSIX and
Windows when source and destination are on the same file system, which is
why the temporary lives beside the destination.

:func:`exclusive_lock` keeps two writers (two batches on one output folder,
two exports into one folder) from interleaving: the second fails at once.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

_UMASK: int | None = None
_UMASK_LOCK = threading.Lock()


def umask() -> int:
    """This process's umask (read once, then remembered).

    POSIX can read the umask only by setting it; while it is set another
    thread (a batch runs jobs in threads) could create a file with the
    temporary value, so it is read once, with the common 022 as that value.
    saucerfab never changes its umask.
    """
    global _UMASK
    with _UMASK_LOCK:
        if _UMASK is None:
            _UMASK = os.umask(0o022)
            os.umask(_UMASK)
        return _UMASK


def sha256_file(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file's bytes (streamed in 1 MiB pieces)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _public(path: str | os.PathLike[str], *, folder: bool) -> None:
    """Give a temporary the permissions a plain open()/mkdir() would have.

    mkstemp and mkdtemp create private (0600 / 0700) entries; an output a
    user or a print bureau's other accounts should read follows the umask.
    """
    os.chmod(path, (0o777 if folder else 0o666) & ~umask())


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file + fsync + rename).

    Returns the final path. Parent folders are created.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        _public(tmp, folder=False)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None:
            # a write or fsync error (a full disk) names no file: name the one being written
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise
    return path


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str], *, overwrite: bool = True) -> Iterator[Path]:
    """Build a folder under a temporary name and move it to ``path`` on success.

    Usage::

        with atomic_dir(out) as tmp:
            (tmp / "a.txt").write_text("...")
        # ``out`` now exists, complete; on an exception nothing is left behind.

    An existing ``path`` is replaced only after the new folder is complete
    (moved aside, then removed), unless ``overwrite`` is false, in which case
    a :class:`FileExistsError` is raised before any work.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent))
    try:
        _public(tmp, folder=True)
        yield tmp
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            os.replace(path, old / "x")
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


@contextlib.contextmanager
def exclusive_lock(
    path: str | os.PathLike[str], busy: Callable[[], BaseException], *, remove: bool = False
) -> Iterator[None]:
    """Hold an exclusive advisory lock on the file ``path`` (created) for the ``with`` block.

    The lock is ``flock`` on the open file, so the kernel frees it when its
    holder dies, even on ``kill -9``: a stale lock file never blocks anyone.
    A second holder, in this process or another, does not wait: ``busy()``
    is raised at once.

    Args:
        path: the lock file; its folder must exist.
        busy: makes the error to raise when another holder has the lock.
        remove: delete the lock file when done (for a lock beside a user's
            folder, where it would be litter). Safe: a holder that locked
            the file just as it was unlinked sees that it holds a file that
            is gone and takes the lock again on the new one.

    On a system without ``fcntl`` (Windows) nothing is locked: one writer per
    folder is then the user's to keep.
    """
    try:
        import fcntl
    except ImportError:
        yield
        return
    path = Path(path)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise busy() from None
        except BaseException:
            os.close(fd)
            raise
        try:
            now = os.stat(path)
        except FileNotFoundError:
            now = None
        held = os.fstat(fd)
        if now is not None and (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino):
            break
        os.close(fd)  # the previous holder removed the file under us: lock the one there now
    try:
        yield
    finally:
        if remove:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)  # while still holding the lock, so nobody else is mid-check on it
        os.close(fd)
