"""Output files that never destroy anything: atomic replacement of regular files only.

Every stage writes through ``atomic_write`` (it lives on the bottom floor, beside
``errors``, so that ``fit``, ``export``, ``fpga`` and ``batch`` can all use it):

- a regular file or a new path is written to an unnamed temporary file in its folder
  (``O_TMPFILE``), which is linked under a temporary name and renamed into place only on
  success, so a reader never sees a half-written file and an interrupted run (an error,
  Ctrl-C, SIGTERM, SIGHUP, even SIGKILL, a full disk) leaves the previous file, or none,
  and no temporary file. Where the file system has no ``O_TMPFILE`` a named temporary file
  is used, removed on errors, Ctrl-C, SIGTERM and SIGHUP. A symbolic link keeps pointing
  where it did (its target is replaced);
- a character device, FIFO or socket (``/dev/null``, ``/dev/stdout`` on a terminal or pipe,
  a named pipe) is written straight through: renaming onto it would replace the device
  node itself;
- an output that is one of the command's inputs (same inode), or an existing directory,
  is refused before any work is done (``check_writable``);
- a file that is replaced keeps its permission bits; a new one gets what ``open()`` would
  give it (0666 less the umask).
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import stat
import sys
import tempfile
import threading
from typing import BinaryIO, Iterable, Iterator

from .errors import OutputError, SourceLocation, UsageError

#: ``errno`` values that mean the disk (or quota) is full: a plan failure, not bad input
_FULL = {28, 122}  # ENOSPC, EDQUOT

#: after Ctrl-C, the time the program has to unwind (discard its output, say so) before it
#: is ended regardless: a compiled kernel can hold a thread for long, and interpreter exit
#: waits for the planning threads
INTERRUPT_GRACE_S = 2.0

_INTERRUPTED = threading.Event()  # Ctrl-C seen: no output is committed after it
_REPORTED = threading.Event()  # the CLI has printed its "interrupted" line


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _stat(path: str) -> os.stat_result | None:
    try:
        return os.stat(path)
    except OSError:
        return None


def _is_stream(st: os.stat_result | None) -> bool:
    """A target written straight through: anything that exists and is not a regular file
    or directory (character/block device, FIFO, socket)."""
    return st is not None and not stat.S_ISREG(st.st_mode) and not stat.S_ISDIR(st.st_mode)


def check_writable(path: str, inputs: Iterable[str] = ()) -> None:
    """Fail now, with the error ``atomic_write`` would give later, when ``path`` cannot be
    written: its folder is missing or not writable, it is a folder, or it is one of the
    command's ``inputs`` (the same file, by inode). Planning a long program first and
    failing at the end would waste the run; writing over the input would destroy it."""
    if path == "-":
        if stdout_closed():
            raise UsageError(_STDOUT_CLOSED)
        return
    loc = SourceLocation(file=path)
    st = _stat(path)
    for name in inputs:
        if name in ("-", None):
            continue
        src = _stat(name)
        if st is not None and src is not None and (st.st_dev, st.st_ino) == (src.st_dev, src.st_ino):
            raise UsageError(f"the output is the input file {name!r}; refusing to overwrite it", loc)
    if _is_stream(st):
        if not os.access(path, os.W_OK):
            raise UsageError("cannot write output: Permission denied", loc)
        return
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise UsageError("cannot write output: Is a directory", loc)
    directory = os.path.dirname(os.path.realpath(path))
    if not os.path.isdir(directory):
        raise UsageError("cannot write output: No such file or directory", loc)
    if not os.access(directory, os.W_OK | os.X_OK):
        raise UsageError("cannot write output: Permission denied", loc)


def _write_error(exc: OSError, path: str) -> Exception:
    loc = SourceLocation(file=path)
    reason = exc.strerror or str(exc)
    if exc.errno in _FULL:
        return OutputError(f"cannot write output: {reason} (the previous file is kept)", loc)
    return UsageError(f"cannot write output: {reason}", loc)


@contextlib.contextmanager
def atomic_write(path: str) -> Iterator[BinaryIO]:
    """Yield a binary file object whose content replaces ``path`` only on success.

    ``path == "-"`` writes to standard output, and a device/FIFO path is written straight
    through (no atomicity is possible there). A ``BrokenPipeError`` from either is left to
    propagate: the CLI turns it into a quiet exit. A write that fails for a full disk is an
    ``OutputError`` (exit 1), any other ``OSError`` a ``UsageError``; the target is unchanged.
    """
    if path == "-":
        out = sys.stdout.buffer
        yield out
        out.flush()
        return
    st = _stat(path)
    if _is_stream(st):
        try:
            fh = open(path, "wb", buffering=1 << 20)
        except OSError as exc:
            raise _write_error(exc, path) from None
        try:
            with fh:
                yield fh
        except OSError as exc:
            if isinstance(exc, BrokenPipeError):
                raise
            raise _write_error(exc, path) from None
        return
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise UsageError("cannot write output: Is a directory", SourceLocation(file=path))
    target = os.path.realpath(path)  # a symlink keeps pointing where it did
    directory = os.path.dirname(target)
    mode = stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~_umask()
    fd, tmp = _open_temp(directory, os.path.basename(target), path)
    linked = None
    try:
        try:
            with os.fdopen(fd, "wb") as fh:
                yield fh
                fh.flush()
                os.fsync(fh.fileno())
                os.fchmod(fh.fileno(), mode)
                if _INTERRUPTED.is_set():  # Ctrl-C, however late, keeps the old file
                    raise KeyboardInterrupt
                if tmp is None:  # an unnamed file: give it a name only now, then rename
                    linked = _temp_name(directory, os.path.basename(target))
                    _link_fd(fh.fileno(), linked)
            os.replace(linked or tmp, target)
        except OSError as exc:
            if isinstance(exc, BrokenPipeError):
                raise
            raise _write_error(exc, path) from None
    except BaseException:  # includes KeyboardInterrupt: never leave the temporary file
        for name in (tmp, linked):
            if name is not None:
                with contextlib.suppress(OSError):
                    os.unlink(name)
        raise
    finally:
        if tmp is not None:
            _TEMPS.discard(tmp)


#: named temporary files being written (the fallback where ``O_TMPFILE`` is not available);
#: the CLI's SIGTERM/SIGHUP handler removes them
_TEMPS: set[str] = set()


def _link_fd(fd: int, name: str) -> None:
    """Give the unnamed file ``fd`` the name ``name``: linkat(2) with AT_SYMLINK_FOLLOW on
    its /proc/self/fd entry (os.link uses plain link(2), which would link the /proc entry
    itself, unless a dir_fd is given)."""
    dfd = os.open("/", os.O_RDONLY)
    try:
        os.link(f"/proc/self/fd/{fd}", name, src_dir_fd=dfd, follow_symlinks=True)
    finally:
        os.close(dfd)


def _temp_name(directory: str, base: str) -> str:
    return os.path.join(directory, f".{base}.{os.getpid()}.{os.urandom(4).hex()}.tmp")


def _open_temp(directory: str, base: str, path: str) -> tuple[int, str | None]:
    """A file descriptor to write the new content to: an unnamed file in ``directory``
    (``O_TMPFILE``: nothing is left behind whatever ends the process, SIGKILL included),
    else a named temporary file (then ``(fd, name)``, registered in ``_TEMPS``)."""
    flag = getattr(os, "O_TMPFILE", 0)
    if flag:
        try:
            return os.open(directory, flag | os.O_WRONLY | os.O_CLOEXEC, 0o600), None
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, errno.ENOENT):
                raise _write_error(exc, path) from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise _write_error(exc, path) from None
    _TEMPS.add(tmp)
    _remove_on_termination()
    return fd, tmp


def _remove_on_termination() -> None:
    """SIGTERM/SIGHUP: remove the named temporary files, then die of the signal as before.
    Installed only when a named temporary file exists, since a Python-level handler runs
    only between bytecodes (it would delay termination during a compiled kernel)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        remove_temporaries()
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)

    for sig in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) in (signal.SIG_DFL, None):
            signal.signal(sig, handler)


def watch_interrupts() -> None:
    """Make Ctrl-C end a long plan promptly and without output.

    SIGINT is blocked in this (the main) thread, and so in every thread started after it,
    and taken by a watcher thread with ``sigwait``, which runs whatever the main thread is
    doing (a Python-level handler waits for it to reach a bytecode). The watcher marks the
    process interrupted (``atomic_write`` then commits nothing), raises
    ``KeyboardInterrupt`` in the main thread, and ends the process with status 130 if it
    is still running ``INTERRUPT_GRACE_S`` later. Call it before any other thread starts;
    elsewhere than in the main thread it does nothing.
    """
    import signal
    import time

    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "sigwait"):
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    # the interrupt may land in a callback (an import lock's weakref, a __del__), where
    # Python can only print it as "Exception ignored" with a traceback; the watcher ends the
    # process anyway, so that report is noise on the user's terminal
    default_hook = sys.unraisablehook

    def quiet_interrupt(unraisable) -> None:
        if not (_INTERRUPTED.is_set() and issubclass(unraisable.exc_type, KeyboardInterrupt)):
            default_hook(unraisable)

    sys.unraisablehook = quiet_interrupt

    def watch() -> None:
        import _thread

        signal.sigwait({signal.SIGINT})
        _INTERRUPTED.set()
        _thread.interrupt_main()
        time.sleep(INTERRUPT_GRACE_S)
        # (a first run's compiling worker ends with this process: its input closes)
        remove_temporaries()  # an unnamed (O_TMPFILE) output vanishes with the process
        if not _REPORTED.is_set():
            os.write(2, b"cnc-interp: interrupted\n")
        os._exit(130)

    threading.Thread(target=watch, daemon=True, name="cnc-interp-sigint").start()


def interrupt_reported() -> None:
    """The CLI printed its one "interrupted" line: the watcher must not print another."""
    _REPORTED.set()


def remove_temporaries() -> None:
    """Delete the named temporary files still being written (for a signal handler that
    is about to end the process)."""
    for name in list(_TEMPS):
        with contextlib.suppress(OSError):
            os.unlink(name)
    _TEMPS.clear()


# -- standard streams closed by the caller (``cnc-interp plan p.ngc >&-``) --------------------
_STDOUT_CLOSED = "cannot write output: standard output is closed"
_STDIN_CLOSED = "cannot read the part program: standard input is closed"


class _ClosedStd(io.RawIOBase):
    """Stands for a standard stream that was closed when the command started: the first
    write (or any read) raises a ``UsageError`` saying so; writes after that first one are
    dropped, so that the flush at exit does not report the same failure again."""

    def __init__(self, message: str, loc: SourceLocation):
        super().__init__()
        self.message, self.loc, self.failed = message, loc, False

    def readable(self) -> bool:
        return True

    def writable(self) -> bool:
        return True

    def readinto(self, buf) -> int:  # type: ignore[no-untyped-def,override]
        raise UsageError(self.message, self.loc)

    def write(self, data) -> int:  # type: ignore[no-untyped-def,override]
        if self.failed:
            return len(data)
        self.failed = True
        raise UsageError(self.message, self.loc)


def stdout_closed() -> bool:
    """Standard output was closed when the command started (``>&-``): nothing written
    there can arrive, so a command writing to it fails with one clear line."""
    out = sys.stdout
    return out is None or isinstance(getattr(getattr(out, "buffer", None), "raw", None), _ClosedStd)


def guard_standard_streams() -> None:
    """Make the process safe to run with standard input, output or error closed.

    A closed descriptor 0, 1 or 2 gets ``/dev/null`` (so no file the command opens takes
    its number: a library's ``printf`` would write into it); Python's ``sys.stdin`` and
    ``sys.stdout`` become streams that fail with a ``UsageError`` on use (reading a part
    program from ``-``, writing a plan or a summary), and ``sys.stderr`` one that discards
    (a complete plan stays a success when nobody reads its summary)."""
    closed = []
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            nul = os.open(os.devnull, os.O_RDWR)
            if nul != fd:
                os.dup2(nul, fd)
                os.close(nul)
            closed.append(fd)
    if 0 in closed or sys.stdin is None:
        raw = _ClosedStd(_STDIN_CLOSED, SourceLocation(file="<stdin>"))
        sys.stdin = io.TextIOWrapper(io.BufferedReader(raw), encoding="utf-8")
    if 1 in closed or sys.stdout is None:
        raw = _ClosedStd(_STDOUT_CLOSED, SourceLocation())
        sys.stdout = io.TextIOWrapper(io.BufferedWriter(raw), encoding="utf-8", write_through=True)
    if 2 in closed or sys.stderr is None:
        sys.stderr = open(2, "w", encoding="utf-8", errors="backslashreplace", closefd=False)


def output_format(path: str, formats: dict[str, str], what: str, stdout: str | None = None) -> str:
    """The format ``path`` is written in, chosen by its suffix (case-insensitive):
    ``formats`` maps each accepted suffix (``".csv"``) to its format, the first being the
    default. ``"-"`` (standard output) is accepted when ``stdout`` names its format, and a
    device or FIFO that exists (``/dev/null``, a named pipe), whose name carries no format,
    takes the default. Any other name is a ``UsageError`` (exit 2) naming the accepted
    suffixes, raised before anything is written."""
    if path == "-":
        if stdout is not None:
            return stdout
    elif path.lower().endswith(tuple(formats)):
        return next(f for s, f in formats.items() if path.lower().endswith(s))
    elif _is_stream(_stat(path)):
        return next(iter(formats.values()))
    names = list(formats) + (["- (standard output)"] if stdout is not None else [])
    listed = ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else names[0]
    suffix = os.path.splitext(path)[1] if path != "-" else ""
    said = f"'{suffix}'" if suffix else ("standard output" if path == "-" else "a name without a suffix")
    raise UsageError(f"{what} cannot be written to {said}: use a name ending in {listed}", SourceLocation(file=path))
