"""Start-up of the ``arboretum`` command (issue 2: "starts in well under a second")."""

from __future__ import annotations

import subprocess
import sys

from bench.harness import Row, median_time


def run() -> list[Row]:
    def python_bare() -> None:
        subprocess.run([sys.executable, "-c", "pass"], check=True)

    def arboretum_help() -> None:
        subprocess.run([sys.executable, "-m", "arboretum_library.cli", "--help"], check=True, capture_output=True)

    base = median_time(python_bare, runs=7)
    t = median_time(arboretum_help, runs=7)
    return [
        Row("arboretum --help (process start to exit)", t, "s", target=0.5, runs=7,
            baseline="python -c pass", ratio=t / base, extra={"baseline_s": base}),
    ]
