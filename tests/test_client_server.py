"""The client against a real ``arboretum serve`` on a random loopback port: synthetic hand events drive
edits and the server's state changes as expected."""

from __future__ import annotations

import tempfile

import numpy as np
import pytest

from arboretum_client.demo import demo_library
from arboretum_library.store import Library


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from arboretum_client.embedded import start_server

    root = tmp_path_factory.mktemp("srv")
    lib = Library.open(root / "lib", create=True)
    lib.add_many(demo_library().values())
    lib.close()
    srv = start_server(root / "lib", root / "state")
    yield srv
    srv.stop()
    assert srv.process.returncode is not None


@pytest.fixture
def client(server):
    from arboretum_client.app import App
    from arboretum_client.headless import OffscreenRenderer
    from arboretum_client.scripts import ScriptRunner
    from arboretum_client.session_remote import RemoteSession

    off = OffscreenRenderer((400, 300))
    holder: list = []
    with off.ctx:
        app = App(off.renderer, lambda: RemoteSession(server.endpoint), out_dir=tempfile.mkdtemp(),
                  clock=lambda: holder[0].clock(), ui=False)
        runner = ScriptRunner(app)
        holder.append(runner)
        app.start()
        runner.settle()
        yield app, runner
        assert off.ctx.error == "GL_NO_ERROR"
        app.close()
    off.close()


def server_assembly(server, app):
    """The assembly as the server has it (a second connection, same session)."""
    from arboretum_library.remote import Remote

    with Remote(server.endpoint) as r:
        return r.assembly(app.worker.port.session).assembly


@pytest.mark.gl
def test_mouse_edits_change_the_server_session(server, client):
    app, runner = client
    assert {r["id"] for r in app.state.library} == set(demo_library())
    runner.run([{"action": "choose:oak-0001"}, {"world": [0, 0, 0]}, {"click": "left"},
                {"action": "choose:pine-0001"}, {"world": [0.8, 0.0, 0]}, {"click": "left"}, {"view": "front"}])
    a = server_assembly(server, app)
    assert [p.example_id for p in a.placements] == ["oak-0001", "pine-0001"]
    pine = a.placements[1]
    base = pine.T_world_example[:3, 3].copy()
    # grip the pine by its main branch and bring it next to the oak's trunk: recombination merges them
    top = app.state.examples["pine-0001"].structure.branches[0].points[4] + base
    runner.run([{"drag": {"from": top.tolist(), "to": (top - base + [0.05, 0.0, 0.0]).tolist()}}])
    a = server_assembly(server, app)
    assert np.linalg.norm(a.placements[1].T_world_example[:3, 3] - base) > 0.5
    moved = a.placements[1].T_world_example[:3, 3]
    assert len(a.merges) == 1 and "merged" in app.state.status, moved
    runner.run([{"hold": "ctrl"}, {"key": "z"}, {"unhold": "ctrl"}])
    a = server_assembly(server, app)
    assert np.allclose(a.placements[1].T_world_example[:3, 3], base) and a.merges == ()


@pytest.mark.gl
def test_grow_and_export_through_the_server(server, client, tmp_path):
    app, runner = client
    runner.run([{"action": "choose:oak-0002"}, {"world": [0, 0, 0]}, {"click": "left"}, {"key": "g"}])
    tree = app.state.grown
    assert tree is not None and len(tree.leaf_centres) > 10
    app.out_dir = tmp_path
    runner.run([{"key": "x"}])
    glb = (tmp_path / "tree.glb").read_bytes()
    assert glb[:4] == b"glTF" and app.state.exported == [str(tmp_path / "tree.glb")]


@pytest.mark.gl
def test_refinement_mode_on_a_real_scan(server, client):
    """Tab opens the scan as a draft on the server; a selected lobe is removed with the menu button."""
    from arboretum_library.assets import asset_path
    from arboretum_library.pointio import ReadOptions, read_points

    app, runner = client
    scan = asset_path("scans", "01_rtwig_coffeetree", "01_rtwig_coffeetree.xyz")
    cloud = read_points(scan, ReadOptions(max_points=4000))
    app.scan = (cloud.points, cloud.labels)
    runner.run([{"key": "tab"}])
    draft = app.state.draft
    assert app.state.mode == "refinement" and draft is not None and len(draft.lobes) >= 3
    assert app.state.cloud is not None and len(app.state.cloud.points) == len(app.state.cloud.labels) > 1000
    assert "points" in app.names.values()  # the cloud is drawn (show point cloud)
    runner.run([{"view": "front"}])
    lobe = draft.lobes[0]
    runner.run([{"world": lobe.centre.tolist()}])
    touched = app.touched["right"]
    assert touched is not None and touched.startswith(("lobe:", "branch:"))
    app.state.selection = ["lobe:0"]
    runner.run([{"key": "delete"}])
    assert len(app.state.draft.lobes) == len(draft.lobes) - 1
    runner.run([{"hold": "ctrl"}, {"key": "z"}, {"unhold": "ctrl"}])
    assert len(app.state.draft.lobes) == len(draft.lobes)


def test_cli_starts_an_embedded_server_and_runs_a_script(server, tmp_path):
    """``arboretum client`` without --connect starts ``arboretum serve`` itself (and stops it, removing
    the temporary folder its autosaves went to)."""
    import json
    import os
    import subprocess
    import sys

    lib = server.process.args[server.process.args.index("--library") + 1]
    script = tmp_path / "s.json"
    script.write_text(json.dumps([{"action": "choose:pine-0002"}, {"world": [0, 0, 0]}, {"click": "left"},
                                  {"key": "x"}]))
    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--library", lib, "--headless", "--script",
           str(script), "--screenshot", str(tmp_path / "shot.png"), "--size", "640x400", "--out", str(tmp_path),
           "--json"]
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=180, env={**os.environ, "TMPDIR": str(scratch)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert sorted(p.name for p in scratch.iterdir() if p.name.startswith("arboretum-client-state-")) == []
    out = json.loads(done.stdout)
    assert out["placements"] == 1 and out["errors"] == [] and out["exported"] == [str(tmp_path / "tree.glb")]
    assert (tmp_path / "tree.glb").read_bytes()[:4] == b"glTF" and (tmp_path / "shot.png").stat().st_size > 1000


def test_the_embedded_servers_own_state_folder_lives_until_stop(tmp_path, monkeypatch):
    # without --state the autosaves go to a temporary folder: there while the server runs (its lock
    # file in it), gone after stop; a folder the caller gave is left alone
    import tempfile

    from arboretum_client.embedded import start_server

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    srv = start_server()
    try:
        assert srv.scratch is not None and srv.scratch.parent == tmp_path and (srv.scratch / ".lock").exists()
    finally:
        srv.stop()
    assert srv.scratch is None and list(tmp_path.glob("arboretum-client-state-*")) == []
    mine = tmp_path / "mine"
    srv = start_server(state=mine)
    srv.stop()
    assert srv.scratch is None and (mine / ".lock").exists()


def test_cli_headless_without_a_script_is_one_clear_error():
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "arboretum_library.cli", "client", "--offline", "--headless"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "--headless needs --script" in done.stderr and "Traceback" not in done.stderr
