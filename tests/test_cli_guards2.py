"""A user's mistake is one clear error before any work, and nothing stored is lost: ``scan``, text
scans with decimal commas, ``keys``, ``assemble``, ``demo`` and ``library build``."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from arboretum_library.assembly import Assembly
from arboretum_library.cli import main
from arboretum_library.codec import load_record
from arboretum_library.errors import InputError
from arboretum_library.pointio import read_points, write_points
from arboretum_library.pointio_text import sniff_not_points
from arboretum_library.store import Library
from factories import build_then_signal, make_example

QSM_HEADER = "start_x,start_y,start_z,axis_x,axis_y,axis_z,length,radius,parent,extension,branch\n"


def _err_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture
def cloud(tmp_path) -> Path:
    rng = np.random.default_rng(3)
    return write_points(tmp_path / "c.xyz", np.c_[rng.normal(0, 0.3, (500, 2)), rng.uniform(0, 4, 500)])


# ---------------------------------------------------------------- scan


def test_scan_convert_refuses_to_overwrite_its_input(cloud, capsys):
    before = cloud.read_bytes()
    assert main(["scan", "convert", str(cloud), str(cloud), "--max-points", "100"]) == 2
    assert "is the input" in _err_line(capsys) and cloud.read_bytes() == before


@pytest.mark.parametrize("extra, words", [
    (["--seed", "-1"], "--seed must not be negative"),
    (["--height", "1e300"], "--height 1e+300: the target height must be a number > 0, from 0.001 to 1000"),
    (["--height", "nan"], "--height nan"),
    (["--max-points", "1"], "--max-points must be at least 2"),
])
def test_scan_convert_bad_options_are_refused_before_reading(cloud, capsys, extra, words):
    out = cloud.parent / "o.ply"
    assert main(["scan", "convert", str(cloud), str(out), *extra]) == 2
    assert words in _err_line(capsys) and not out.exists()


def test_scan_without_subcommand_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["scan"])
    assert e.value.code == 2 and "required: SUBCOMMAND" in capsys.readouterr().err


# ---------------------------------------------------------------- decimal commas, cylinder tables


@pytest.mark.parametrize("row", ["-9,679 1,25 3,152", "-9,679;1,25;3,152", "-9,679\t1,25\t3", "1,5e-3 2,0 3,0"])
def test_decimal_commas_are_refused_not_misread(tmp_path, row):
    path = tmp_path / "comma.xyz"
    path.write_text("x y z\n" + "\n".join([row] * 5) + "\n")
    with pytest.raises(InputError, match=r"line 2: .* decimal comma; decimal commas\? convert them to points"):
        read_points(path)


@pytest.mark.parametrize("text, first", [
    ("1.5,2.5,3.5\n4.5,5.5,6.5\n7,8,9.25\n", [1.5, 2.5, 3.5]),
    ("1.5, 2.5, 3.5\n4.5, 5.5, 6.5\n7, 8, 9.25\n", [1.5, 2.5, 3.5]),
    ("x,y,z\n1,2,3\n4,5,6\n7,8,10\n", [1, 2, 3]),
    ("x;y;z\n1.5;2;3\n4;5;6\n7;8;10\n", [1.5, 2, 3]),
    ("x ,y ,z\n-625 ,265 ,516\n1 ,2 ,3\n4 ,5 ,6\n", [-625, 265, 516]),  # a space before each comma (a reviewer's)
])
def test_comma_separated_files_still_read(tmp_path, text, first):
    (tmp_path / "s.csv").write_text(text)
    points = read_points(tmp_path / "s.csv").points
    assert points.shape == (3, 3) and sorted(map(tuple, points))[0] == tuple(first)


def test_cylinder_tables_and_licences_are_not_point_clouds(tmp_path, scans_dir):
    qsm = tmp_path / "QSM_cylinders.csv"
    qsm.write_text("# TreeQSM cylinders\n" + QSM_HEADER + "0.1,0.2,0.0,0,0,1,0.5,0.1,0,2,1\n" * 5)
    with pytest.raises(InputError, match="is a cylinder table .* not a point cloud"):
        read_points(qsm)
    assert "cylinder table" in sniff_not_points(qsm)
    assert "cylinder table" in sniff_not_points(scans_dir / "01_rtwig_coffeetree" / "QSM_treeqsm_cylinders.csv")
    assert "licence" in sniff_not_points(scans_dir / "10_treels_pine" / "LICENSE.TreeLS.txt")
    assert sniff_not_points(scans_dir / "06_adtree_tree7" / "06_adtree_tree7.xyz") is None


# ---------------------------------------------------------------- keys


def test_keys_client_named_server_is_refused(tmp_path, capsys):
    assert main(["keys", "generate", str(tmp_path / "K")]) == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "K").iterdir() if p.is_file()}
    capsys.readouterr()
    for name in ("server", "Server"):
        assert main(["keys", "generate", str(tmp_path / "K"), "--client", name, "--force"]) == 2
        assert "names the server's own key files" in _err_line(capsys)
    assert {p.name: p.read_bytes() for p in (tmp_path / "K").iterdir() if p.is_file()} == before
    assert main(["keys", "generate", str(tmp_path / "new"), "--client", "server"]) == 2
    assert not (tmp_path / "new").exists()


def test_adding_a_client_keeps_the_server_key_and_the_other_clients(tmp_path, capsys):
    k = tmp_path / "K"
    assert main(["keys", "generate", str(k)]) == 0
    server = (k / "server.key").read_bytes(), (k / "server.key_secret").read_bytes()
    client = (k / "clients" / "client.key").read_bytes()
    capsys.readouterr()
    assert main(["keys", "generate", str(k), "--client", "alice", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["server_key"] == "kept" and out["client_public"] == str(k / "clients" / "alice.key")
    assert ((k / "server.key").read_bytes(), (k / "server.key_secret").read_bytes()) == server
    assert sorted(p.name for p in (k / "clients").iterdir()) == ["alice.key", "client.key"]
    alice = (k / "clients" / "alice.key").read_bytes()
    assert main(["keys", "generate", str(k), "--client", "alice"]) == 2
    assert "already holds keys for the client 'alice'" in _err_line(capsys)
    assert main(["keys", "generate", str(k), "--client", "alice", "--force"]) == 0
    assert (k / "clients" / "alice.key").read_bytes() != alice
    assert ((k / "server.key").read_bytes(), (k / "clients" / "client.key").read_bytes()) == (server[0], client)


def test_a_client_added_later_can_connect(tmp_path):
    import shutil
    import threading

    from arboretum_library.remote import Remote
    from arboretum_server.service.cli import curve_keys
    from arboretum_server.service.context import Context
    from arboretum_server.service.dispatch import Dispatcher
    from arboretum_server.service.jobs import JobRunner
    from arboretum_server.service.sessions import Sessions
    from arboretum_server.service.socket import Server

    k, alice = tmp_path / "K", tmp_path / "alice"
    main(["keys", "generate", str(k)])
    main(["keys", "generate", str(k), "--client", "alice"])
    alice.mkdir()
    for name in ("server.key", "alice.key_secret"):  # what the server's admin gives alice
        shutil.copy(k / name, alice / name)
    keys, auth = curve_keys(str(k))
    server = Server(Dispatcher(Context(Sessions(tmp_path / "state"))), "tcp://127.0.0.1:0", jobs=JobRunner(1),
                    curve_secret=keys)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        for folder in (alice, k):  # k: its client.key_secret (alice.key_secret is used only when chosen by name)
            with Remote(server.endpoint, curve=folder, timeout=5) as r:
                assert r.welcome is not None
    finally:
        server.stop_event.set()
        thread.join(10)
        auth.stop()


# ---------------------------------------------------------------- assemble


@pytest.fixture
def lib(tmp_path) -> Path:
    rng = np.random.default_rng(8)
    with Library.open(tmp_path / "lib", create=True) as lb:
        for i in range(2):
            lb.add(make_example(rng, id=f"ex-{i}", n_lobes=3))
    return tmp_path / "lib"


SCRIPT = "- add: {example: ex-0, as: trunk}\n- add: {example: ex-1, as: limb, at: [0, 0, 0.4]}\n"


def test_assemble_refuses_to_overwrite_its_script_but_updates_a_session(tmp_path, lib, capsys):
    script = tmp_path / "a.yaml"
    script.write_text(SCRIPT)
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(script)]) == 2
    assert "writes .npz files, not .yaml" in _err_line(capsys) and script.read_text() == SCRIPT
    session = tmp_path / "s.npz"
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(session), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["placements"]
    more = tmp_path / "more.yaml"
    more.write_text("- add: {example: ex-0, as: third, at: [2, 0, 0]}\n")
    # --from and --out the same session: read whole first, replaced at the end (the demo does this)
    assert main(["assemble", str(more), "--library", str(lib), "--from", str(session), "--out", str(session),
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["placements"] == [*first, "third"]
    assert [p.instance for p in load_record(session, Assembly).placements] == [*first, "third"]


def test_assemble_binary_script_is_one_error(tmp_path, lib, capsys):
    script = tmp_path / "pic.yaml"
    script.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "o.npz")]) == 2
    assert "pic.yaml: not a text file" in _err_line(capsys)


def test_assemble_reads_a_library_it_cannot_lock(tmp_path, lib, capsys):
    script = tmp_path / "a.yaml"
    script.write_text(SCRIPT)
    (lib / ".lock").unlink(missing_ok=True)
    (lib / ".lock").mkdir()  # no write lock can be taken: reading needs none
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "o.npz")]) == 0
    assert (tmp_path / "o.npz").is_file()
    capsys.readouterr()
    (lib / "catalog.sqlite").unlink()  # rebuilding the catalog needs the lock: one error naming the library
    assert main(["assemble", str(script), "--library", str(lib), "--out", str(tmp_path / "p.npz")]) == 2
    err = _err_line(capsys)
    assert f"--library {lib}: cannot open the library" in err and ".lock" in err
    assert main(["assemble", str(script), "--library", str(tmp_path / "none"), "--out", str(tmp_path / "p.npz")]) == 2
    assert "does not exist" in _err_line(capsys) and not (tmp_path / "none").exists()


# ---------------------------------------------------------------- demo


def test_demo_refuses_a_folder_of_the_users_files(tmp_path, capsys):
    (tmp_path / "U").mkdir()
    (tmp_path / "U" / "tree.glb").write_text("my own tree")
    assert main(["demo", "--out", str(tmp_path / "U"), "--no-client"]) == 2
    assert "holds files that are not a demo's (tree.glb)" in _err_line(capsys)
    assert [p.name for p in (tmp_path / "U").iterdir()] == ["tree.glb"]
    assert main(["demo", "--out", str(tmp_path / "V"), "--seed", "-1", "--no-client"]) == 2
    assert "--seed must not be negative" in _err_line(capsys) and not (tmp_path / "V").exists()
    (tmp_path / "f").write_text("x")
    assert main(["demo", "--out", str(tmp_path / "f"), "--no-client"]) == 2
    assert "is a file" in _err_line(capsys)


def test_demo_rerun_replaces_its_own_library(tmp_path, monkeypatch, capsys):
    from arboretum_library.commands import demo

    runs = []

    def fake_stages(seed):  # one stage that adds an example to the demo's library, as decompose does
        return [demo.Stage("add", ("x",))]

    def fake_run_stage(stage, out, i, n):
        lib = out / "library"
        lib.mkdir(exist_ok=True)
        (lib / f"example-{len(list(lib.iterdir()))}").write_text("x")
        runs.append(len(list(lib.iterdir())))
        return {"stage": stage.name, "seconds": 0.0}

    monkeypatch.setattr(demo, "stages", fake_stages)
    monkeypatch.setattr(demo, "run_stage", fake_run_stage)
    out = tmp_path / "out"
    for _ in range(2):
        assert main(["demo", "--out", str(out), "--no-client", "--json"]) == 0
    assert runs == [1, 1]  # the second run started from an empty library
    assert "holds a previous demo: replacing it" in capsys.readouterr().err
    assert (out / demo.MARKER).is_file() and json.loads((out / "demo.json").read_text())["stages"]
    old = tmp_path / "old"  # a demo folder from before the marker: recognised by its demo.json
    old.mkdir()
    (old / "demo.json").write_text(json.dumps({"stages": []}))
    (old / "library").mkdir()
    assert demo.prepare_out(old) is True and not (old / "library").exists()


# ---------------------------------------------------------------- library build


@pytest.mark.parametrize("extra, words", [
    (["--points", "1"], "--points 1 leaves too few points"),
    (["--seed", "-1"], "--seed must not be negative"),
    (["--height", "inf"], "--height must be a finite number >= 0"),
])
def test_build_options_are_checked_before_any_scan(tmp_path, cloud, capsys, extra, words):
    lib = tmp_path / "B"
    assert main(["library", "build", str(cloud), "--library", str(lib), *extra]) == 2
    assert words in _err_line(capsys) and not lib.exists()


def test_build_missing_scan_or_report_file_is_refused_up_front(tmp_path, cloud, capsys):
    lib = tmp_path / "B"
    assert main(["library", "build", str(tmp_path / "nonexist.xyz"), "--library", str(lib)]) == 2
    assert "SCAN" in _err_line(capsys) and not lib.exists()
    (tmp_path / "rep").write_text("mine")
    assert main(["library", "build", str(cloud), "--library", str(lib), "--report", str(tmp_path / "rep")]) == 2
    assert "--report" in _err_line(capsys) and not lib.exists()
    assert (tmp_path / "rep").read_text() == "mine"
    # a report inside the library: a build that stored nothing removed both (a reviewer's case)
    assert main(["library", "build", str(cloud), "--library", str(lib), "--report", str(lib / "report")]) == 2
    assert "is inside --library" in _err_line(capsys) and not lib.exists()


def test_build_leaves_out_cylinder_tables(tmp_path):
    from arboretum_server.batch.build import expand_scans

    (tmp_path / "a.xyz").write_text("0 0 0\n1 1 1\n0 1 2\n")
    (tmp_path / "QSM.csv").write_text(QSM_HEADER + "0,0,0,0,0,1,1,0.1,0,2,1\n")
    ignored: list = []
    (tmp_path / "README.txt").write_text("Scans of the park.\nSee the licence.\n")  # short prose (a reviewer's)
    assert expand_scans([str(tmp_path)], ignored) == [str(tmp_path / "a.xyz")]
    assert sorted((Path(p).name, "cylinder table" in why) for p, why in ignored) == [("QSM.csv", True),
                                                                                    ("README.txt", False)]
    with pytest.raises(InputError, match=r"no scans given: .*QSM.csv is a cylinder table"):
        expand_scans([str(tmp_path / "QSM.csv")])


def test_build_exit_status_and_no_empty_library_left(tmp_path, capsys):
    from arboretum_server.batch.synthetic import synthetic_scans

    broken = tmp_path / "broken.xyz"
    broken.write_text("this is not\na point cloud 1 2\n")
    lib = tmp_path / "B1"
    assert main(["library", "build", str(broken), "--library", str(lib), "--workers", "1", "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert (data["failed"], data["added"], data["library_kept"]) == (1, 0, False) and not lib.exists()
    good = synthetic_scans(tmp_path / "good", 1, points=1500)
    lib2 = tmp_path / "B2"
    args = ["library", "build", str(good[0]), str(broken), "--library", str(lib2), "--workers", "1",
            "--points", "1500"]
    assert main(args) == 1
    out = capsys.readouterr().out
    assert "1 scan added" in out and "1 failed" in out
    with Library.open(lib2, readonly=True) as L:
        assert len(L) >= 1
    assert main(args[:3] + args[4:]) == 0  # the good scan alone: already there, nothing failed
    assert "0 scans added" in capsys.readouterr().out


def test_local_workers_ignore_sigint():
    from arboretum_server.batch.build import BuildOptions, _Cluster

    handler = signal.getsignal(signal.SIGINT)
    with _Cluster(BuildOptions(workers=1)) as (client, _, _):
        seen = list(client.run(lambda: signal.getsignal(signal.SIGINT) == signal.SIG_IGN).values())
        assert signal.getsignal(signal.SIGINT) is handler  # the client keeps its Ctrl-C
    assert seen == [True]


@pytest.mark.slow
def test_ctrl_c_in_the_terminal_stops_the_build_quietly(tmp_path):
    code, text, _, _ = build_then_signal(tmp_path, 12, 3000, lambda p: os.killpg(p.pid, signal.SIGINT))  # Ctrl-C: the group
    assert code == 130 and "Traceback" not in text and "KeyboardInterrupt" not in text
    assert "still alive" not in text and text.strip().endswith("arboretum library: interrupted")
