"""``library export`` on a full disk (review s10, finding 3): a failing write() is an ``OSError`` with no
file name; it must come out as one line naming ARCHIVE, with the temporary file removed. A library file
that cannot be read is the library's error, never blamed on the archive."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.archive import export_archive
from arboretum_library.errors import StoreError
from arboretum_library.store import Library
from factories import make_example

# the real thing: RLIMIT_FSIZE makes write() fail with EFBIG, as ENOSPC would on a full disk
_CHILD = """
import resource, signal, sys
from arboretum_library.cli import main
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[1]), int(sys.argv[1])))
sys.exit(main(['library', 'export', sys.argv[2], sys.argv[3]]))
"""


@pytest.fixture
def lib_path(tmp_path) -> Path:
    rng = np.random.default_rng(3)
    with Library.open(tmp_path / "lib", create=True, fsync=False) as lib:
        for i in range(3):
            lib.add(make_example(rng, id=f"ex-{i}", n_lobes=3))
    return tmp_path / "lib"


def test_a_write_past_the_file_size_limit_names_the_archive_and_leaves_no_temp_file(lib_path, tmp_path):
    with Library.open(lib_path, fsync=False) as lib:
        size = export_archive(lib, tmp_path / "whole.tar")["size_bytes"]
    out = tmp_path / "out"
    out.mkdir()
    r = subprocess.run([sys.executable, "-c", _CHILD, str(size // 2), str(lib_path), str(out / "a.tar")],
                       capture_output=True, text=True, timeout=120)
    last = r.stderr.strip().splitlines()[-1]
    assert "Traceback" not in r.stderr, r.stderr
    assert (r.returncode, last) == (2, f"arboretum library: error: ARCHIVE {out / 'a.tar'}: cannot write it "
                                       f"({os.strerror(errno.EFBIG)})")
    assert list(out.iterdir()) == []  # neither the archive nor its temporary file


def test_a_library_file_that_cannot_be_read_is_a_store_error_not_the_archives(lib_path, tmp_path, monkeypatch):
    real = Path.read_bytes

    def read_bytes(self):
        if self.name == "arrays.npz" and self.parent.name == "ex-1":
            raise OSError(errno.EIO, os.strerror(errno.EIO))  # a failing read() names no file either
        return real(self)

    monkeypatch.setattr(Path, "read_bytes", read_bytes)
    with Library.open(lib_path, fsync=False) as lib, pytest.raises(StoreError) as info:
        export_archive(lib, tmp_path / "a.tar")
    folder = lib_path / "examples" / "ex-1"
    assert str(info.value) == f"{folder}: cannot read the example ({os.strerror(errno.EIO)})"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib"]
