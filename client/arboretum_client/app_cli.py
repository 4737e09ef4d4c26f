"""``arboretum client``: the interactive client (desktop window, VR, or a headless script).

    arboretum client [--connect ADDRESS [--curve KEYDIR] | --offline] [--library LIB] [--scan FILE]
                     [--size WxH] [--headless] [--script S] [--screenshot out.png] [--vr] [--out DIR] [--json]
                     [--reference IMAGE [--reference-height METRES]]

Without ``--connect`` (and without ``--offline``, which uses built-in demo examples and no server) an
embedded ``arboretum serve`` starts as a child process on a free loopback port and stops on exit.
``--curve KEYDIR`` connects to a ``serve --curve`` server with CurveZMQ keys (``Remote(curve=...)``).
``--headless`` renders with EGL (no display); ``--script`` feeds recorded input (see
``arboretum_client.scripts``), in a window too; ``--screenshot`` saves the last frame. ``--vr`` uses an
OpenXR runtime when one is present and otherwise says why and opens the desktop window.
``--reference`` shows a PNG/JPEG as a billboard standing behind the origin (key B hides/shows it); a
script may name one too (top-level key ``reference``, relative to the script's folder).

Arguments and the script's steps are checked before a window opens or a server starts (``check_args``,
``script_check.check_steps``): a bad one is one error line and exit code 2.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

from arboretum_library.cli import add_json_flag, emit
from arboretum_library.pointio import SCAN_UP_CHOICES


def register(subparsers) -> None:
    p = subparsers.add_parser("client", help="the interactive tree-modeling client (desktop, VR or headless)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--connect", metavar="ADDRESS", help="server endpoint, e.g. tcp://127.0.0.1:5555")
    where.add_argument("--offline", action="store_true", help="no server: built-in demo examples in memory")
    p.add_argument("--curve", metavar="KEYDIR", help="CurveZMQ keys for --connect: a folder from 'arboretum keys "
                   "generate' (its client.key_secret, or its only client secret) or one NAME.key_secret beside server.key")
    p.add_argument("--library", metavar="LIB", help="an existing example library for the embedded server")
    p.add_argument("--scan", metavar="FILE", help="point cloud to refine (refinement mode, Tab)")
    p.add_argument("--up", choices=SCAN_UP_CHOICES, default="auto",
                   help="the way up of the --scan file: z, y, z-down or y-down (upside down) (default: "
                        "guessed, as 'arboretum scan info' does)")
    p.add_argument("--species", default="unknown",
                   help="species of the --scan tree: N_m and N_l from VRTree Table 2 (default: unknown, 8 and 40)")
    p.add_argument("--main", type=int, metavar="N", help="main branches of the --scan decomposition (overrides --species)")
    p.add_argument("--lobes", type=int, metavar="N", help="lobes of the --scan decomposition (overrides --species)")
    p.add_argument("--leaf-off", action="store_true",
                   help="the --scan tree bore no leaves: the draft reports every point as wood")
    p.add_argument("--size", default="1280x720", help="window or image size WIDTHxHEIGHT (default 1280x720)")
    p.add_argument("--headless", action="store_true", help="render without a display (EGL); needs --script")
    p.add_argument("--script", metavar="S", help="JSON/YAML script of input events and tool actions")
    p.add_argument("--screenshot", metavar="PNG", help="save the last frame as PNG")
    p.add_argument("--vr", action="store_true", help="use an OpenXR headset when a runtime is present")
    p.add_argument("--reference", metavar="IMAGE", help="PNG/JPEG shown behind the tree for image-guided modeling")
    p.add_argument("--reference-height", type=float, default=None, metavar="METRES",
                   help="height of the reference image in metres (default 1.0; width from its aspect)")
    p.add_argument("--out", default=".", metavar="DIR", help="folder for exports and session saves (default .)")
    p.add_argument("--frames", type=int, default=0, help=argparse.SUPPRESS)  # window tests: close after N frames
    add_json_flag(p)
    p.set_defaults(func=run)


def _port_factory(args, cleanup: list):
    """A zero-argument function making the session port (run on the worker thread)."""
    if args.offline:
        from .session_fake import FakeSession

        return FakeSession
    from .session_remote import RemoteSession

    endpoint = args.connect
    if endpoint is None:
        from .embedded import start_server

        server = start_server(args.library)
        cleanup.append(server.stop)
        endpoint = server.endpoint
    curve = getattr(args, "curve", None)  # only with --connect (check_args)
    return lambda: RemoteSession(endpoint, curve=curve)


def _scan(path: str | None, up: str = "auto", species: str = "unknown", main: int | None = None,
          lobes: int | None = None, leaf_off: bool = False):
    """The ``app.Scan`` of ``--scan`` read with ``--up``, with ``--species``, ``--main``, ``--lobes`` and
    ``--leaf-off``, or None. The counts are checked by the server when Tab opens the scan (one status line)."""
    if not path:
        return None
    from arboretum_library.pointio import ReadOptions, read_points

    from .app import Scan

    cloud = read_points(path, ReadOptions(up=up))
    options = {k: v for k, v in (("n_main", main), ("n_lobes", lobes)) if v is not None}
    options |= {"leaf_off": True} if leaf_off else {}
    return Scan(cloud.points, getattr(cloud, "labels", None), Path(path).name, species, options)


def _reference(args):
    """The reference billboard from ``--reference`` or else the script's ``reference`` key, or None."""
    from .app import load_reference, reference_billboard
    from .scripts import script_reference

    path, height = script_reference(args.script) if args.script else (None, None)
    if args.reference:
        path = args.reference
    if args.reference_height is not None:
        height = args.reference_height
    if path is None:
        return None
    return reference_billboard(load_reference(path), 1.0 if height is None else height)


ENDPOINT = re.compile(r"tcp://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(\d{1,5})|ipc://\S+")
"""What ``--connect`` accepts: tcp://HOST:PORT (a name, an IPv4 address or a bracketed IPv6 one) or ipc://PATH."""


def check_args(args: argparse.Namespace) -> tuple[int, int]:
    """Refuse bad startup arguments before a window opens or a server starts; returns the size."""
    from arboretum_library.errors import InputError
    from arboretum_library.folders import check_marker

    from .render_cli import parse_size

    size = parse_size(args.size)
    if args.headless and not args.script:
        raise InputError("--headless needs --script S (there is no one to click)")
    counts = {k: getattr(args, k, None) for k in ("main", "lobes")}
    given = [f"--{k}" for k, v in counts.items() if v is not None]
    given += ["--species"] * (getattr(args, "species", "unknown") != "unknown")
    given += ["--up"] * (getattr(args, "up", "auto") != "auto")
    given += ["--leaf-off"] * bool(getattr(args, "leaf_off", False))
    if given and not getattr(args, "scan", None):
        raise InputError(f"{', '.join(given)} apply to the --scan file, and no --scan was given")
    for k, v in counts.items():
        if v is not None and v < 1:
            raise InputError(f"--{k} must be at least 1, got {v}")
    if args.connect is not None:
        m = ENDPOINT.fullmatch(args.connect.strip())
        if m is None or (m.group(2) is not None and not 0 < int(m.group(2)) < 65536):
            raise InputError(f"--connect: {args.connect!r} is not a server address (tcp://HOST:PORT, e.g. "
                             "tcp://127.0.0.1:5555, or ipc://PATH)")
    _check_curve(args)
    if args.library is not None:
        if args.offline or args.connect is not None:
            raise InputError("--library is the embedded server's library: with --offline or --connect it would "
                             "be ignored (a running server has its own --library)")
        try:
            check_marker(Path(args.library), create=False)
        except InputError as exc:
            raise InputError(f"--library: {exc} (the client opens an existing library; make one with "
                             "'arboretum serve --library DIR' or 'arboretum decompose ... --library DIR')") from None
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise InputError(f"--out {args.out}: is a file, not a folder")
    return size


def _check_curve(args: argparse.Namespace) -> None:
    """``--curve`` only with ``--connect``, and its keys readable (one error line, before any window)."""
    from arboretum_library.errors import InputError
    from arboretum_library.remote import client_keys

    curve = getattr(args, "curve", None)
    if curve is None:
        return
    if args.connect is None:
        raise InputError("--curve KEYDIR needs --connect ADDRESS (the embedded server and --offline use no keys)")
    try:
        client_keys(curve)
    except InputError as exc:
        raise InputError(f"--curve: {exc}") from None


def run(args: argparse.Namespace) -> int:
    size = check_args(args)
    args.steps = _script_steps(args)  # checked here: a bad step is one error line before any window
    args.reference_item = _reference(args)  # before the server starts: a bad image is a quick error
    scan = _scan(args.scan, args.up, args.species, args.main, args.lobes, args.leaf_off)
    cleanup: list = []
    try:
        factory = _port_factory(args, cleanup)
        if args.headless:
            data = _run_headless(args, size, factory, scan)
        else:
            data = _run_interactive(args, size, factory, scan)
    finally:
        for fn in cleanup:
            fn()
    emit(args, data, f"{data['frames']} frames, {data['placements']} placements, status: {data['status']}")
    return 0


def _summary(app, runner_frames: int, shots) -> dict:
    s = app.state
    return {"frames": runner_frames, "placements": len(s.assembly.placements), "revision": s.revision,
            "refine_revision": s.refine_revision, "lobes": len(s.draft.lobes) if s.draft is not None else None,
            "status": s.status, "errors": s.errors, "screenshots": [str(p) for p in shots],
            "draw_calls": app.renderer.stats.draw_calls, "exported": s.exported}


def _script_steps(args) -> list:
    """The script's steps (plus the ``--screenshot``), checked (``script_check.check_steps``)."""
    from .script_check import check_steps
    from .scripts import load_script

    steps = list(load_script(args.script)["steps"]) if args.script else []
    if args.screenshot:
        steps.append({"screenshot": str(Path(args.screenshot).resolve())})
    check_steps(steps)
    return steps


def _run_headless(args, size, factory, scan) -> dict:
    from .app import App
    from .headless import OffscreenRenderer
    from .scripts import ScriptRunner

    with OffscreenRenderer(size) as off, off.ctx:
        holder: list = []
        app = App(off.renderer, factory, args.out, clock=lambda: holder[0].clock(), scan=scan,
                  reference=args.reference_item)
        runner = ScriptRunner(app, base=Path("."))
        holder.append(runner)
        try:
            app.start()
            shots = runner.run(args.steps)
            return _summary(app, int(round(runner.now / runner.dt)), shots)
        finally:
            app.close()


def _run_interactive(args, size, factory, scan) -> dict:
    from .context import open_window

    if args.vr:
        from .input.openxr import VrUnavailable, open_runtime

        try:
            return _run_vr(args, open_runtime(), factory, scan)
        except VrUnavailable as exc:
            print(f"VR: {exc}", file=sys.stderr)
    win = open_window(size, "Arboretum")
    try:
        return _window_loop(args, win, factory, scan)
    finally:
        win.close()


def _window_loop(args, win, factory, scan) -> dict:
    import glfw

    from .app import App
    from .render.renderer import Renderer
    from .scripts import ScriptRunner
    from .window_input import install_callbacks

    renderer = Renderer(win.ctx, glfw.get_framebuffer_size(win.handle))  # pixels: 2x the window on HiDPI
    app = App(renderer, factory, args.out, scan=scan, reference=args.reference_item)
    install_callbacks(win.handle, app)
    app.start()
    shots, frames = [], 0
    try:
        if args.script or args.screenshot:  # scripted: virtual time, same App, shown in the window
            runner = ScriptRunner(app, base=Path("."))
            app.clock = runner.clock
            app.actions.clock = runner.clock
            shots = runner.run(args.steps)
            frames = int(round(runner.now / runner.dt))
        last = time.monotonic()
        while not glfw.window_should_close(win.handle) and not (args.script and frames) and \
                not (args.frames and frames >= args.frames):
            glfw.poll_events()
            now = time.monotonic()
            app.update(now - last)
            last = now
            renderer.render(app.desktop.camera)
            renderer.present(win.ctx.screen)
            win.swap()
            frames += 1
        return _summary(app, frames, shots)
    finally:
        app.close()
        renderer.release()


def _run_vr(args, runtime, factory, scan) -> dict:
    """Untested here (no OpenXR runtime): the logic in ``VrSession`` is tested with a fake runtime."""
    from .app import App
    from .context import current_context
    from .input.openxr import VrSession
    from .render.renderer import Renderer

    ctx = current_context()
    sc = runtime.context.swapchains[0]  # type: ignore[attr-defined]
    renderer = Renderer(ctx, (sc.width, sc.height))
    app = App(renderer, factory, args.out, scan=scan, ui=False, reference=args.reference_item)
    app.start()
    try:
        frames = VrSession(app, runtime).run(args.frames or None)
        return _summary(app, frames, [])
    finally:
        app.close()
        runtime.close()
