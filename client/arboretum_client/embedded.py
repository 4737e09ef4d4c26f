"""Start ``arboretum serve`` as a child process on a free loopback port (when no --connect is given).

The child is the same Python running ``arboretum_library.cli serve --bind tcp://127.0.0.1:0``; it prints
``listening on ENDPOINT`` once bound. ``stop`` sends SIGTERM (the server snapshots its sessions) and
kills it if it does not exit in time. Without ``state`` the autosaves go to a temporary folder that
``stop`` removes: nobody could find them again, and every run would leave one behind.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from arboretum_library.errors import ArboretumError


class ServerStartError(ArboretumError):
    code = "server_start"


@dataclass
class EmbeddedServer:
    process: subprocess.Popen
    endpoint: str
    log: list[str] = field(default_factory=list)
    """The child's stderr lines (for error messages)."""
    scratch: Path | None = None
    """The temporary state folder made for this server (removed by ``stop``), or None."""

    def stop(self, timeout: float = 10.0) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)
        if self.scratch is not None:
            shutil.rmtree(self.scratch, ignore_errors=True)
            self.scratch = None


def start_server(library: str | os.PathLike | None = None, state: str | os.PathLike | None = None,
                 timeout: float = 60.0, workers: int = 1) -> EmbeddedServer:
    """Run ``arboretum serve`` on ``tcp://127.0.0.1:0``; returns once it listens (``ServerStartError``
    with its last log lines if it exits or stays silent for ``timeout`` seconds)."""
    scratch = None if state else Path(tempfile.mkdtemp(prefix="arboretum-client-state-"))
    state = Path(state) if state else scratch
    cmd = [sys.executable, "-m", "arboretum_library.cli", "serve", "--bind", "tcp://127.0.0.1:0",
           "--state", str(state), "--workers", str(workers)]
    if library:
        cmd += ["--library", str(library)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log: list[str] = []
    threading.Thread(target=lambda: log.extend(proc.stderr), daemon=True).start()  # type: ignore[arg-type]
    found: list[str] = []

    def read() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("listening on "):
                found.append(line.split("listening on ", 1)[1].strip())
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    end = time.monotonic() + timeout
    while not found and proc.poll() is None and time.monotonic() < end:
        time.sleep(0.02)
    if not found:
        server = EmbeddedServer(proc, "", log, scratch)
        server.stop()
        tail = " | ".join(line.strip() for line in log[-3:])
        raise ServerStartError(f"the embedded server did not start ({tail or 'no output'})")
    return EmbeddedServer(proc, found[0], log, scratch)
