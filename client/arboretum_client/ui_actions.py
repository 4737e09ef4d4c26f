"""The panel, shortcut and script actions: the one table ``App.ui_action`` runs and ``script_check`` accepts.

An action is a name (``"grow"``, a ``SIMPLE`` entry) or ``HEAD:ARG`` (``"tag:dense"``, a ``WITH_ARG``
entry). Each entry is a function of the ``App`` (and the argument), so adding an action here makes the
app run it and the script checker accept it at once. Plain data and lambdas: no GL, no glfw.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    from .app import App

TAGS = ("straight", "curved", "dense", "sparse")
"""The library's tag filters: a button each in the library panel, ``tag:T`` as an action."""
TOGGLES = ("show_points", "show_all")
"""The ``ClientState`` flags that ``toggle:NAME`` flips."""
SESSION_FILE = "session.npz"
"""The file ``save`` writes and ``load`` reads, in the app's output folder."""

SIMPLE: dict[str, Callable[[App], object]] = {
    "undo": lambda app: app.actions.undo(),
    "redo": lambda app: app.actions.redo(),
    "menu": lambda app: app.interaction.menu(),
    "touchpad": lambda app: app.interaction.touchpad(),
    "grow": lambda app: app.actions.grow(),
    "export": lambda app: app.actions.export(app.out_dir),
    "mode": lambda app: app.toggle_mode(),
    "save": lambda app: app.actions.save(app.out_dir / SESSION_FILE),
    "commit": lambda app: app.actions.commit_refinement(),
    "load": lambda app: app.actions.load(app.out_dir / SESSION_FILE),
    "noop": lambda app: None,
    "reference": lambda app: app.toggle_reference(),
}
"""Action name -> what it does to the app."""


class ArgAction(NamedTuple):
    """An action with an argument (``HEAD:ARG``)."""

    run: Callable[[App, str], object]
    """What it does to the app, given ARG (the app runs any ARG; the script checker is stricter)."""
    choices: tuple[str, ...] | None = None
    """The ARGs a script may give; None: any (see ``needs``)."""
    needs: str = ""
    """When not '': ARG must not be blank, and this says what it names (for the checker's message)."""


def _tag(app: App, arg: str) -> None:
    s = app.state
    s.tag_filter = "" if s.tag_filter == arg else arg
    app.actions.refresh_library()


def _toggle(app: App, arg: str) -> None:
    setattr(app.state, arg, not getattr(app.state, arg))
    app.state.touch_scene()


def _density(app: App, arg: str) -> None:
    """``density:+`` grows the density by a quarter, anything else shrinks it by a fifth."""
    app.actions.set_density(app.state.density * (1.25 if arg == "+" else 0.8))


def _focus(app: App, _arg: str) -> None:
    app.state.focus += 1
    app.state.touch_scene()


WITH_ARG: dict[str, ArgAction] = {
    "search": ArgAction(lambda app, _arg: setattr(app.state, "search_focus", True)),
    "tag": ArgAction(_tag, TAGS),
    "choose": ArgAction(lambda app, arg: app.actions.choose(arg), needs="an example id, e.g. choose:oak-0001"),
    "toggle": ArgAction(_toggle, TOGGLES),
    "density": ArgAction(_density, ("+", "-")),
    "focus": ArgAction(_focus),
}
"""HEAD -> the action ``HEAD:ARG``."""


def run_action(app: App, action: str) -> None:
    """Run ``action`` on ``app`` (an unknown one does nothing: the script checker refuses it first)."""
    simple = SIMPLE.get(action)
    if simple is not None:
        simple(app)
        return
    head, _, arg = action.partition(":")
    entry = WITH_ARG.get(head)
    if entry is not None:
        entry.run(app, arg)
