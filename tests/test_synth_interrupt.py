"""Ctrl-C while a numba kernel of ``arboretum synth`` runs: one line, exit 130, no files, no traceback.

Before ``synth.interrupt``, numba wrapped the KeyboardInterrupt in a SystemError (a 40-line traceback,
exit 1) during the path search, and a Ctrl-C during the Yao-graph kernels could end in a segmentation
fault (exit 139).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from arboretum_server.synth.interrupt import interruptible

# The child replaces the path-search kernel with a wrapper that, on the 4th search (the longest: about
# 0.9 s on 400,000 nodes), has a timer send SIGINT to the process 0.1 s into the compiled search.
CHILD = """
import os, signal, sys, threading
import arboretum_server.synth.kernels as kernels
from arboretum_library.cli import main
search, calls = kernels.lazy_search, []
def search_then_ctrl_c(*args):
    calls.append(1)
    if len(calls) == 4:
        print("searching", flush=True)
        threading.Timer(0.1, os.kill, (os.getpid(), signal.SIGINT)).start()
    return search(*args)
kernels.lazy_search = search_then_ctrl_c
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_during_the_path_search_stops_quietly(tmp_path):
    argv = [sys.executable, "-c", CHILD, "synth", "--nodes", "400000", "--out", str(tmp_path / "s.ply"),
            "--truth", str(tmp_path / "t.npz"), "--mesh", str(tmp_path / "m.glb")]
    proc = subprocess.run(argv, capture_output=True, timeout=300, start_new_session=True,
                          env={**os.environ, "OMP_WAIT_POLICY": "PASSIVE"})
    err = proc.stderr.decode().replace("\r", "\n")
    assert proc.stdout.decode() == "searching\n"  # the signal came during the 4th search
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "SystemError" not in err and "Fatal" not in err
    assert err.strip().endswith("arboretum synth: interrupted")
    assert list(tmp_path.iterdir()) == []  # no scan, truth, mesh or temporary file


@pytest.mark.skipif(signal.getsignal(signal.SIGINT) is not signal.default_int_handler,
                    reason="needs Python's own Ctrl-C handler")  # fmt: skip
def test_interruptible_defers_ctrl_c_to_the_end_of_the_block():
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with interruptible():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler runs here, and only notes the signal
            steps.append("finished")
    assert steps == ["finished"] and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with interruptible():
        steps.append("no signal")
    with pytest.raises(ValueError, match="other"), interruptible():
        raise ValueError("other errors pass through")
    assert steps == ["finished", "no signal"] and signal.getsignal(signal.SIGINT) is signal.default_int_handler
