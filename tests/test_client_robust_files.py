"""A failed load, save or export is a status line; the client and its session carry on (helper-52 bug 1)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile

import numpy as np
import pytest

from arboretum_client.app import App
from arboretum_client.headless import OffscreenRenderer
from arboretum_client.input.desktop import Key
from arboretum_client.net import Worker
from arboretum_client.scripts import ScriptRunner
from arboretum_client.session_fake import FakeSession
from arboretum_library.assembly import Assembly
from arboretum_library.codec import load_record
from arboretum_library.errors import InputError

PLACE = [{"action": "choose:oak-0001"}, {"world": [0, 0, 0]}, {"click": "left"}]


@pytest.fixture
def client():
    off = OffscreenRenderer((320, 240))
    off.ctx.__enter__()
    holder: list = []
    app = App(off.renderer, FakeSession, out_dir=tempfile.mkdtemp(), clock=lambda: holder[0].clock(), ui=False)
    runner = ScriptRunner(app)
    holder.append(runner)
    app.start()
    runner.settle()
    yield app, runner
    app.close()
    off.ctx.__exit__(None, None, None)
    off.close()


@pytest.mark.gl
def test_failed_load_and_save_leave_the_session_and_a_later_save_works(client, tmp_path):
    app, runner = client
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where the --out folder should be")
    app.out_dir = blocker / "out"  # cannot be created (even as root): its parent is a file
    runner.run(PLACE)
    assert len(app.state.assembly.placements) == 1

    runner.run([{"hold": "ctrl"}, {"key": "o"}, {"unhold": "ctrl"}])  # Ctrl+O before any save
    assert app.state.status.startswith("load failed: ") and "session.npz: no such file" in app.state.status
    assert len(app.state.assembly.placements) == 1 and app.state.revision == 1

    runner.run([{"hold": "ctrl"}, {"key": "s"}, {"unhold": "ctrl"}])  # Ctrl+S into an unwritable folder
    assert app.state.status.startswith("save failed: cannot write ") and str(blocker) in app.state.status
    assert [e.split(":")[0] for e in app.state.errors] == ["load", "save"]

    runner.run([{"action": "export"}])
    assert app.state.status.startswith("export failed: cannot write ") and app.state.exported == []

    app.out_dir = tmp_path / "good"
    runner.run([{"action": "save"}])
    assert app.state.status == "saved session.npz"
    saved = load_record(tmp_path / "good" / "session.npz", Assembly)
    assert [p.example_id for p in saved.placements] == ["oak-0001"]
    assert np.allclose(saved.placements[0].T_world_example, app.state.assembly.placements[0].T_world_example)

    runner.run([{"action": "load"}])
    assert app.state.status == "loaded session.npz"
    assert [p.example_id for p in app.state.assembly.placements] == ["oak-0001"]


def test_a_user_error_raised_by_a_done_callback_goes_to_on_error_and_a_bug_still_raises():
    worker = Worker(FakeSession)
    errors: list = []

    def bad_file(_result):
        raise OSError(13, "Permission denied", "/nowhere/x.npz")

    worker.submit("save", lambda p, _: 1, bad_file, errors.append)
    assert worker.wait_idle(10)
    assert len(errors) == 1 and isinstance(errors[0], OSError) and errors[0].filename == "/nowhere/x.npz"

    worker.submit("bug", lambda p, _: 1, lambda _r: 1 / 0, errors.append)
    with pytest.raises(ZeroDivisionError):
        worker.wait_idle(10)
    worker.close()


def test_a_user_error_in_a_window_callback_becomes_the_status_line():
    from arboretum_client.window_input import handle_safely

    class Fake:
        def __init__(self, exc):
            from arboretum_client.tools.state import ClientState

            self.state, self.exc = ClientState(), exc

        def handle(self, _event):
            raise self.exc

    app = Fake(InputError("session.npz: no such file"))
    handle_safely(app, Key("o"))
    assert app.state.status == "failed: session.npz: no such file" and app.state.errors == ["session.npz: no such file"]
    with pytest.raises(KeyError):  # a bug keeps its traceback
        handle_safely(Fake(KeyError("x")), Key("o"))


@pytest.mark.gl
def test_cli_ctrl_o_before_any_save_keeps_running_and_takes_the_screenshot(tmp_path):
    script = tmp_path / "s.json"
    steps = [*PLACE, {"hold": "ctrl"}, {"key": "o"}, {"unhold": "ctrl"}, {"wait": 0.2}, {"screenshot": "after.png"}]
    script.write_text(json.dumps(steps))
    (tmp_path / "fresh").mkdir()
    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--offline", "--headless", "--script", str(script),
           "--out", str(tmp_path / "fresh"), "--size", "640x480", "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads(done.stdout)
    assert summary["placements"] == 1 and summary["status"].startswith("load failed:")
    assert summary["screenshots"] == ["after.png"] and (tmp_path / "after.png").stat().st_size > 1000


@pytest.fixture
def actions():
    from arboretum_client.tools.actions import Actions
    from arboretum_client.tools.state import ClientState

    worker = Worker(FakeSession)
    yield Actions(ClientState(), worker)
    worker.close()


def _record_threads(monkeypatch, name: str) -> list[str]:
    """Wrap ``tools.actions.<name>`` so each call records the thread it ran on."""
    import threading

    from arboretum_client.tools import actions as module

    threads: list[str] = []
    real = getattr(module, name)

    def wrapped(*args, **kwargs):
        threads.append(threading.current_thread().name)
        return real(*args, **kwargs)
    monkeypatch.setattr(module, name, wrapped)
    return threads


def test_save_writes_its_file_on_the_worker_thread_not_in_the_frame_loop(actions, tmp_path, monkeypatch):
    threads = _record_threads(monkeypatch, "save_record")
    path = tmp_path / "sub" / "session.npz"
    actions.save(path)
    assert actions.worker.wait_idle(10)
    assert threads == ["arboretum-net"] and actions.state.status == "saved session.npz"
    assert load_record(path, Assembly).placements == ()
    assert sorted(p.name for p in path.parent.iterdir()) == ["session.npz"]  # no temp file left


def test_export_writes_its_file_on_the_worker_thread_and_reports_the_size(actions, tmp_path, monkeypatch):
    threads = _record_threads(monkeypatch, "write_atomic")
    actions.export(tmp_path / "out")
    assert actions.worker.wait_idle(10)
    written = tmp_path / "out" / "tree.obj"
    assert threads == ["arboretum-net"] and actions.state.exported == [str(written)]
    assert actions.state.status == f"exported tree.obj ({written.stat().st_size} bytes)"
    assert sorted(p.name for p in written.parent.iterdir()) == ["tree.obj"]


def test_save_and_export_into_an_unwritable_folder_are_status_lines_and_write_nothing(actions, tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    actions.save(blocker / "out" / "session.npz")
    assert actions.worker.wait_idle(10)
    assert actions.state.status == f"save failed: cannot write {blocker / 'out' / 'session.npz'} (Not a directory)"
    actions.export(blocker / "out")
    assert actions.worker.wait_idle(10)
    assert actions.state.status == f"export failed: cannot write {blocker / 'out' / 'tree.obj'} (Not a directory)"
    assert actions.state.exported == [] and [e.split(":")[0] for e in actions.state.errors] == ["save", "export"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]
