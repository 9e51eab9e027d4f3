"""A run's temporary folders removed even when the master is SIGKILLed.

The master can remove what it made unless it is killed outright (SIGKILL, the OOM killer): then
its workers die with it (PR_SET_PDEATHSIG) and the extracted FMUs (master-run-*) and the raw
results (master_results_*) would stay in the temporary folder. A janitor, a small shell started
at the beginning of the run in a session of its own (a signal to the terminal's process group is
not for it), reads a pipe whose write end only the master and its workers hold:
it learns the folders through the pipe, one a line, and, when the pipe ends without the master's
"done" (every holder died), removes them. The results CSV is not among them: the rows written so
far stay. A shell, not a fork of the master: it starts and ends in a fraction of a millisecond,
where a copy of the master's memory costs milliseconds on each side.
"""

from __future__ import annotations

import os
import subprocess

SCRIPT = (
    'trap "" INT TERM HUP; '  # signals are the master's to handle (the shell has a session of its own)
    'while IFS= read -r f; do [ "$f" = done ] && exit 0; set -- "$@" "$f"; done; '  # collect ...
    'rm -rf -- "$@"'  # ... and at the end of the pipe without "done", remove
)


class Janitor:
    """`j = Janitor(); j.watch(folder); ...; j.close()` (close: the janitor ends, removing nothing)."""

    def __init__(self) -> None:
        read, self._write = os.pipe()
        try:  # only the pipe's read end: no copy of the master's other pipes (its stdout, its workers')
            self._proc: subprocess.Popen | None = subprocess.Popen(
                ["/bin/sh", "-c", SCRIPT],
                stdin=read,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                close_fds=True,
                start_new_session=True,  # out of the terminal's process group: Ctrl-C, a group's kill
            )
        except BaseException:
            os.close(self._write)
            raise
        finally:
            os.close(read)

    def watch(self, folder: str | os.PathLike) -> None:
        """Remove `folder` should the master die before `close` (a path on more than one line,
        which no temporary folder has, is not watched)."""
        path = os.fsencode(os.path.abspath(folder))
        if b"\n" not in path:
            self._send(path + b"\n")

    def close(self) -> None:
        """End the janitor without it removing anything; wait for it (no process is left)."""
        if self._proc is None:
            return
        self._send(b"done\n")  # the master closed normally: it removes (or keeps) its folders itself
        os.close(self._write)
        self._proc.wait()
        self._proc = None

    def _send(self, data: bytes) -> None:
        try:
            os.write(self._write, data)  # a path is shorter than PIPE_BUF: written at once
        except OSError:  # the janitor is gone (killed on its own): nothing to tell
            pass
