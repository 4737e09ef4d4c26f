"""Refinement in the client as a user drives it (session 13, helper-110's hunt): strokes drawn with the
mouse land on the scan, lobes selected decide the touchpad, a commit's ids stay on the status line, the
refinement revision is kept, and missing input is said."""

from __future__ import annotations

import numpy as np
import pytest

from arboretum_library.assets import asset_path
from arboretum_library.pointio import ReadOptions, read_points
from test_client_server import client, server  # noqa: F401  (fixtures: a real server, a headless client)

pytestmark = pytest.mark.gl


def _open(app, runner):
    cloud = read_points(asset_path("scans", "01_rtwig_coffeetree", "01_rtwig_coffeetree.xyz"),
                        ReadOptions(max_points=4000))
    app.scan = (cloud.points, cloud.labels, "coffee.xyz")
    runner.run([{"key": "tab"}, {"view": "iso"}])
    assert app.state.draft is not None
    return app.state.cloud


def _front_lobe(app) -> int:
    """The lobe nearest the camera among those of 30 points or more."""
    cloud, eye = app.state.cloud, app.desktop.camera.eye
    lobes = [j for j in range(len(app.state.draft.lobes)) if (cloud.lobe_of == j).sum() >= 30]
    return min(lobes, key=lambda j: np.linalg.norm(cloud.points[cloud.lobe_of == j].mean(axis=0) - eye))


def _two_strokes(app) -> tuple[int, list, list]:
    """(lobe, first, second): the lobe nearest the camera, of 30 points or more, on which two strokes drawn over
    its two halves (5 of its points each, along its longest extent across the line of sight) land on points
    not all shared. A stroke lands on the point nearest the eye within the brush (5 cm) of the cursor's ray
    (``Interaction._on_cloud``): on a lobe 4-9 cm across, or behind another, two one-point strokes along its
    longest extent landed on one point (session 30's lobes)."""
    from types import SimpleNamespace

    cloud, eye = app.state.cloud, app.desktop.camera.eye
    lobes = [j for j in range(len(app.state.draft.lobes)) if (cloud.lobe_of == j).sum() >= 30]
    lobes.sort(key=lambda j: np.linalg.norm(cloud.points[cloud.lobe_of == j].mean(axis=0) - eye))

    def lands(p) -> tuple:  # where the client lands a cursor over p: the same call a mouse sample makes
        ray = (np.asarray(p) - eye) / np.linalg.norm(np.asarray(p) - eye)
        return tuple(app.interaction._on_cloud(SimpleNamespace(position=eye, ray_dir=ray, pixel=(0, 0))))

    for j in lobes:
        line = _stroke_over(cloud, j, eye, np.linspace(0.0, 1.0, 10))
        first, second = line[:5], line[5:]
        if {lands(p) for p in second} - {lands(p) for p in first}:
            return j, first, second
    raise AssertionError("no lobe takes two strokes landing apart")


def _stroke_over(cloud, lobe: int, eye: np.ndarray, at=(0.2, 0.5, 0.8)) -> list[list[float]]:
    """Points of ``lobe`` at fractions ``at`` of its longest extent as seen from ``eye`` (across the line of sight:
    along it, two far-apart points can fall under one pixel, and two strokes there pick the same points)."""
    pts = cloud.points[cloud.lobe_of == lobe]
    c = pts.mean(axis=0)
    sight = (c - eye) / np.linalg.norm(c - eye)
    flat = (pts - c) - np.outer((pts - c) @ sight, sight)
    axis = np.linalg.svd(flat)[2][0]
    order = np.argsort((pts - c) @ axis)
    return [pts[order[int(f * (len(order) - 1))]].tolist() for f in at]


def test_a_mouse_stroke_over_the_scan_selects_the_points_under_it(client):  # noqa: F811
    app, runner = client
    cloud = _open(app, runner)
    lobe = _front_lobe(app)
    stroke = _stroke_over(cloud, lobe, app.desktop.camera.eye)
    runner.run([{"stroke": stroke}])
    picked = app.state.point_selection
    assert len(picked) >= 5  # 0 when the stroke lay on the plane through the camera target
    gap = np.linalg.norm(cloud.points[picked][:, None] - np.array(stroke)[None], axis=2).min(axis=1)
    assert np.median(gap) < 0.1
    before = app.state.refine_revision
    runner.run([{"key": "enter"}])
    assert app.state.status.startswith("insert lobe") and app.state.refine_revision == before + 1


def test_split_strokes_drawn_over_a_lobe_split_it(client):  # noqa: F811
    app, runner = client
    _open(app, runner)
    lobe, first, second = _two_strokes(app)
    n = len(app.state.draft.lobes)
    runner.run([{"select": f"lobe:{lobe}"}, {"stroke": first}, {"stroke": second}, {"key": "enter"}])
    assert app.state.status == f"split lobe: {n + 1} lobes", app.state.status


def test_lobes_selected_decide_over_points_selected_before(client):  # noqa: F811
    app, runner = client
    _open(app, runner)
    n = len(app.state.draft.lobes)
    app.state.point_selection = np.arange(50, dtype=np.int64)
    runner.run([{"select": ["lobe:1", "lobe:4"]}, {"key": "enter"}])
    assert len(app.state.draft.lobes) == n - 1 and app.state.status.startswith("merge lobes")
    assert app.state.strokes == [] and len(app.state.point_selection) == 0


def test_a_commit_leaves_its_ids_on_the_status_line(server, client):  # noqa: F811
    from arboretum_library.remote import Remote

    app, runner = client
    _open(app, runner)
    runner.run([{"key": "c"}])
    first = app.state.status
    assert first.startswith("stored ") and first.count(",") >= 1, first
    with Remote(server.endpoint) as r:  # the examples name the scan file, not 'scan'
        assert r.get_example(first[len("stored "):].split(",")[0].strip()).provenance.source == "coffee.xyz"
    runner.run([{"key": "c"}])
    assert "committed already" in app.state.status  # and not "N examples" from the library refresh


def test_delete_with_no_lobe_selected_says_what_it_needs(client):  # noqa: F811
    app, runner = client
    _open(app, runner)
    runner.run([{"key": "delete"}])
    assert app.state.status == "menu: select a lobe to remove it"


def test_tab_without_a_scan_says_so(client):  # noqa: F811
    app, runner = client
    runner.run([{"key": "tab"}])
    assert app.state.status == "refinement: no scan to refine; start the client with --scan FILE"
    assert app.state.draft is None


def test_up_axis_of_the_scan_can_be_given():
    from arboretum_client.app_cli import _scan

    auto = _scan(str(asset_path("synth", "guiding_hanging_s2.ply"))).points
    z, labels, name, species, options = _scan(str(asset_path("synth", "guiding_hanging_s2.ply")), "z", "pine", 3)
    assert (species, options) == ("pine", {"n_main": 3})
    assert round(float(np.ptp(z[:, 2])), 2) == 8.43 and round(float(np.ptp(auto[:, 2])), 2) == 12.2
    assert name == "guiding_hanging_s2.ply" and int(labels.sum()) == 4586


def test_show_one_names_the_example_shown(client):  # noqa: F811
    from arboretum_client.ui.refine_panel import _shown
    from arboretum_library.model import Level

    app, runner = client
    _open(app, runner)
    mains = sum(b.level == Level.MAIN for b in app.state.draft.branches)
    app.state.focus = mains + 1  # N pressed past the last one: the second is shown again
    assert _shown(app.state) == f"2 of {mains}"


def test_species_and_counts_of_the_scan_reach_the_server(client):  # noqa: F811
    """A pine refined with its Table 2 counts, or with --main/--lobes (the client always asked for 8 and 40)."""
    from arboretum_library.model import Level

    app, runner = client
    cloud = read_points(asset_path("scans", "01_rtwig_coffeetree", "01_rtwig_coffeetree.xyz"),
                        ReadOptions(max_points=4000))
    from arboretum_client.app import Scan

    app.scan = Scan(cloud.points, cloud.labels, "coffee.xyz", "unknown", {"n_main": 3, "n_lobes": 12})
    runner.run([{"key": "tab"}])
    draft = app.state.draft
    assert len(draft.lobes) == 12 and sum(b.level == Level.MAIN for b in draft.branches) == 3


@pytest.mark.parametrize("argv, message", [
    (["--main", "3"], "--main apply to the --scan file, and no --scan was given"),
    (["--species", "pine", "--up", "z"], "--species, --up apply to the --scan file"),
    (["--scan", "x.xyz", "--lobes", "0"], "--lobes must be at least 1, got 0"),
])
def test_scan_options_without_a_scan_or_out_of_range_are_refused(argv, message, capsys):
    from arboretum_library.cli import main

    assert main(["client", "--offline", "--headless", "--script", "s.json", *argv]) == 2
    assert message in capsys.readouterr().err


def test_a_select_after_a_failed_open_says_why_the_scene_is_empty(client):  # noqa: F811
    from arboretum_library.errors import InputError

    app, runner = client
    tiny = read_points(asset_path("scans", "01_rtwig_coffeetree", "01_rtwig_coffeetree.xyz"),
                       ReadOptions(max_points=300)).points
    app.scan = (tiny, None, "tiny.xyz")
    with pytest.raises(InputError) as err:
        runner.run([{"key": "tab"}, {"select": "lobe:1"}])
    assert "nothing is pickable now; decompose failed: lobes: 40 asked for 300 points" in str(err.value)


def test_points_selected_do_not_survive_a_visit_to_modeling(client):  # noqa: F811
    """helper-110: a stroke's points kept through Tab -> modeling -> Tab could be inserted much later."""
    app, runner = client
    _open(app, runner)
    app.state.point_selection = np.arange(50, dtype=np.int64)
    runner.run([{"key": "tab"}, {"key": "tab"}])
    assert app.state.mode == "refinement" and len(app.state.point_selection) == 0
