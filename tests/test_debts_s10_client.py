"""One table of actions for the app and the script checker (``ui_actions``), one home per UI constant,
and a cursor scale asked of glfw only when the framebuffer changes."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from arboretum_client.app import App
from arboretum_client.script_check import check_action
from arboretum_client.tools.state import REFINEMENT, ClientState
from arboretum_client.ui_actions import SIMPLE, TAGS, WITH_ARG

OUT = Path("/nowhere/out")
EXPECTED_SIMPLE = {
    "undo": [("actions.undo", ())], "redo": [("actions.redo", ())], "menu": [("interaction.menu", ())],
    "touchpad": [("interaction.touchpad", ())], "grow": [("actions.grow", ())],
    "export": [("actions.export", (OUT,))], "mode": [("toggle_mode", ())],
    "save": [("actions.save", (OUT / "session.npz",))], "commit": [("actions.commit_refinement", ())],
    "load": [("actions.load", (OUT / "session.npz",))], "noop": [], "reference": [("toggle_reference", ())],
}
"""What each simple action did in ``App.ui_action`` before the table moved (the behaviour to keep)."""


class _Recorder:
    def __init__(self, prefix: str, calls: list):
        self._prefix, self._calls = prefix, calls

    def __getattr__(self, name):
        return lambda *args: self._calls.append((f"{self._prefix}.{name}", args))


def _fake_app():
    calls: list = []
    app = SimpleNamespace(state=ClientState(), actions=_Recorder("actions", calls),
                          interaction=_Recorder("interaction", calls), out_dir=OUT, calls=calls)
    app.toggle_mode = lambda: calls.append(("toggle_mode", ()))
    app.toggle_reference = lambda: calls.append(("toggle_reference", ()))
    return app


def _accepted_actions() -> list[str]:
    """Every action form the checker's table describes."""
    out = list(SIMPLE)
    for head, entry in WITH_ARG.items():
        out += [f"{head}:{c}" for c in entry.choices] if entry.choices else [f"{head}:oak-0001", f"{head}:"]
    return out


@pytest.mark.parametrize("action", sorted(EXPECTED_SIMPLE))
def test_each_simple_action_runs_what_it_ran_before(action):
    app = _fake_app()
    App.ui_action(app, action)
    assert app.calls == EXPECTED_SIMPLE[action]
    assert app.state.ui_version == 1


def test_the_checker_accepts_exactly_the_simple_actions_the_app_runs():
    assert set(SIMPLE) == set(EXPECTED_SIMPLE)
    assert all(check_action(a) is None for a in EXPECTED_SIMPLE)
    for bad in ("fly", "undo:x", "zoom:+", "Grow", ""):
        assert check_action(bad).startswith(f"unknown action {bad!r}"), bad


def test_every_action_the_checker_accepts_does_something_in_the_app():
    for action in _accepted_actions():
        if action == "choose:":
            assert check_action(action) == "choose: needs an example id, e.g. choose:oak-0001"
            continue
        assert check_action(action) is None, action
        app = _fake_app()
        before = (app.state.search_focus, app.state.tag_filter, app.state.show_points, app.state.show_all,
                  app.state.focus, app.state.scene_version)
        App.ui_action(app, action)
        after = (app.state.search_focus, app.state.tag_filter, app.state.show_points, app.state.show_all,
                 app.state.focus, app.state.scene_version)
        assert action == "noop" or app.calls or after != before, action


def test_argument_actions_change_the_state_as_before():
    app = _fake_app()
    App.ui_action(app, "tag:dense")
    assert app.state.tag_filter == "dense" and app.calls == [("actions.refresh_library", ())]
    App.ui_action(app, "tag:dense")
    assert app.state.tag_filter == ""
    App.ui_action(app, "toggle:show_points")
    assert app.state.show_points is False and app.state.scene_version == 1
    App.ui_action(app, "focus:+")
    assert app.state.focus == 1 and app.state.scene_version == 2
    App.ui_action(app, "search:focus")
    assert app.state.search_focus is True
    app.calls.clear()
    App.ui_action(app, "density:+")
    App.ui_action(app, "density:-")
    App.ui_action(app, "choose:pine-0002")
    assert app.calls == [("actions.set_density", (1.25,)), ("actions.set_density", (0.8,)),
                         ("actions.choose", ("pine-0002",))]
    App.ui_action(app, "fly")  # refused by the checker; the app does nothing but redraw
    assert len(app.calls) == 3 and app.state.ui_version == 9 + 2  # 9 actions, 2 touch_scene


def test_the_checker_refuses_arguments_outside_the_table():
    assert check_action("tag:bushy") == "tag: expects one of straight, curved, dense, sparse, got 'bushy'"
    assert check_action("toggle:grid") == "toggle: expects one of show_points, show_all, got 'grid'"
    assert check_action("density:*") == "density: expects one of +, -, got '*'"
    assert check_action("choose:  ") == "choose: needs an example id, e.g. choose:oak-0001"
    assert check_action("search") is None and check_action("focus") is None


def test_every_shortcut_and_every_panel_button_is_an_action_the_checker_accepts():
    from arboretum_client.net import JobStatus
    from arboretum_client.ui.layout import draw_ui

    assert all(check_action(a) is None for a in App.KEYS.values())
    modeling = ClientState(library=[{"id": "oak-0001", "lobe_count": 3, "tags": ["dense"]}])
    refining = ClientState(mode=REFINEMENT)
    jobs = {1: JobStatus("grow", 0.5, "growing")}
    actions = [a for s in (modeling, refining) for _, a in draw_ui((1280, 720), s, jobs).regions]
    assert {f"tag:{t}" for t in TAGS} | {"choose:oak-0001", "commit", "touchpad", "menu"} <= set(actions)
    assert [a for a in actions if check_action(a) is not None] == []


def test_panel_width_margin_and_character_width_keep_their_pixels():
    from arboretum_client.ui import library_panel, refine_panel
    from arboretum_client.ui.layout import panel_width
    from arboretum_client.ui.widgets import Canvas

    assert panel_width((1280, 720)) == 250 and panel_width((200, 720)) == 180
    c = Canvas((1280, 720))
    library_panel.draw(c, ClientState())  # default width: the panel's
    boxes = dict((a, b) for b, a in c.regions)
    assert boxes["search:focus"] == (18, 38, 252, 56)
    x, want = 18, {}
    for tag in TAGS:
        want[f"tag:{tag}"] = (x, x + 8 + 7 * len(tag))
        x += 8 + 7 * len(tag) + 4
    assert {t: boxes[t][::2] for t in want} == want
    assert boxes["undo"][2] - boxes["undo"][0] == 10 + 7 * len("undo")
    c = Canvas((1280, 720))
    refine_panel.draw(c, ClientState(mode=REFINEMENT))
    first_box, first_action = c.regions[0]
    assert first_action == "menu" and first_box[:3] == (18, first_box[1], 18 + 10 + 7 * len("remove lobe"))


def test_the_cursor_scale_is_asked_once_and_again_only_on_a_framebuffer_change(monkeypatch):
    glfw = pytest.importorskip("glfw")
    from arboretum_client.input.desktop import MouseMove
    from arboretum_client.window_input import install_callbacks

    callbacks, asked = {}, []
    sizes = {"window": (640, 360), "framebuffer": (1280, 720)}
    for name in ("cursor_pos", "mouse_button", "scroll", "key", "framebuffer_size"):
        monkeypatch.setattr(glfw, f"set_{name}_callback", lambda _w, cb, name=name: callbacks.__setitem__(name, cb))
    monkeypatch.setattr(glfw, "get_window_size", lambda w: asked.append(w) or sizes["window"])
    monkeypatch.setattr(glfw, "get_framebuffer_size", lambda _w: sizes["framebuffer"])
    app = SimpleNamespace(events=[], sizes=[])
    app.handle, app.resize = app.events.append, app.sizes.append

    install_callbacks("win", app)
    for i in range(5):
        callbacks["cursor_pos"]("win", 10.0 * i, 5.0)
    assert asked == ["win"] and app.events[-1] == MouseMove(80.0, 10.0)
    sizes["framebuffer"] = (640, 360)  # moved to a low-density screen: nothing asked until the callback
    callbacks["cursor_pos"]("win", 100.0, 50.0)
    assert app.events[-1] == MouseMove(200.0, 100.0) and asked == ["win"]
    callbacks["framebuffer_size"]("win", 640, 360)
    callbacks["cursor_pos"]("win", 100.0, 50.0)
    assert app.events[-1] == MouseMove(100.0, 50.0) and asked == ["win", "win"] and app.sizes == [(640, 360)]
    sizes["window"] = (0, 0)
    callbacks["framebuffer_size"]("win", 0, 0)  # minimised: keep the last size and scale
    callbacks["cursor_pos"]("win", 30.0, 20.0)
    assert app.events[-1] == MouseMove(30.0, 20.0) and len(asked) == 2 and app.sizes == [(640, 360)]
