"""A run's temporary folders removed even when the master is SIGKILLed.

The master can remove what it made unless it is killed outright (SIGKILL, the OOM killer): then
its workers die with it (PR_SET_PDEATHSIG) and the extracted FMUs (master-run-*) and the raw
results (master_results_*) would stay in the temporary folder. A janitor, a process forked at the
start of the run, holds the read end of a pipe whose write end only the master and its workers
hold: it learns the folders through the pipe and, when the pipe ends without the master's "done"
(every holder died), removes them. The results CSV is not among them: the rows written so far stay.
"""

from __future__ import annotations

import os
import shutil
import signal

SEP = b"\0"  # ends each message: "+" and a folder's path, or DONE
DONE = b"done"  # the master closed normally: it removes (or keeps) its folders itself


class Janitor:
    """`j = Janitor(); j.watch(folder); ...; j.close()` (close: the janitor ends, removing nothing)."""

    def __init__(self) -> None:
        read, self._write = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the janitor: nothing but the pipe and the file system
            try:
                _keep_only(read)  # no copy of the master's other pipes (its stdout, its workers')
                _watch(read)
            finally:
                os._exit(0)
        os.close(read)

    def watch(self, folder: str | os.PathLike) -> None:
        """Remove `folder` should the master die before `close`."""
        self._send(b"+" + os.fsencode(folder) + SEP)

    def close(self) -> None:
        """End the janitor without it removing anything; wait for it (no process is left)."""
        if self.pid is None:
            return
        self._send(DONE + SEP)
        os.close(self._write)
        os.waitpid(self.pid, 0)
        self.pid = None

    def _send(self, data: bytes) -> None:
        try:
            os.write(self._write, data)  # a path is shorter than PIPE_BUF: written at once
        except OSError:  # the janitor is gone (killed with the master's process group): nothing to tell
            pass


def _keep_only(fd: int) -> None:
    """Close every file descriptor but `fd` (the standard streams: /dev/null)."""
    null = os.open(os.devnull, os.O_RDWR)
    for std in (0, 1, 2):
        os.dup2(null, std)
    os.closerange(3, fd)
    os.closerange(fd + 1, os.sysconf("SC_OPEN_MAX"))


def _watch(read: int) -> None:
    """The janitor's life: collect folders until "done" (return) or the end of the pipe (remove them)."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # the master's to handle: Ctrl-C
        signal.signal(sig, signal.SIG_IGN)  # reaches the whole process group, the janitor too
    received = b""
    while chunk := os.read(read, 4096):
        received += chunk
        if DONE in received.split(SEP)[:-1]:
            return
    for message in received.split(SEP)[:-1]:
        shutil.rmtree(os.fsdecode(message[1:]), ignore_errors=True)
