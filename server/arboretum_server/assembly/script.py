"""Run a checked assembly script (``script_check.Op``) through the service's handlers, in this process.

Three rules on top of the handlers, for a pipeline that runs a script and trusts its files:

- ``transform`` and ``transform_lobe`` change only the keys they give: ``at``, the rotation
  (``rotate`` / ``rotate_z``) and ``scale`` each keep the instance's (or the lobe's) current value
  when left out, read from the session as the operation runs;
- the session an ``undo`` can go back to is the one the script started from: undoing the loading of a
  ``--from`` session is "nothing to undo", as in a fresh script;
- an export (and ``--out``, through ``stage``) writes its file beside its destination under a hidden
  temporary name, ``.NAME.PID-N.tmp``; ``commit`` puts every such file in place once all operations
  succeeded, all or none (``swap``), and ``close`` removes those left, so a script that fails (or is
  interrupted) leaves no export behind.

``swap`` (``atomic.replace_all``) first keeps each destination's present file under a second hidden
name, ``.NAME.PID-N.old`` (a hard link, so the destination stays in place; moved aside where the folder
has no hard links), then renames the new files in. An ``OSError`` at any step (a folder made read-only, a destination that
became a folder, a full disk) undoes the steps done, in reverse: every destination holds what it held
before (a missing one is missing again), the temporary files go, and one ``InputError`` names the
destination and the problem. On success the ``.old`` files go. Ctrl-C is held back over the whole
swap. A SIGKILL during it can leave ``.NAME.PID-N.tmp`` (the new file) and ``.NAME.PID-N.old`` (the
previous one) beside a destination; neither is ever read, and either may be removed.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly, Placement
from arboretum_library.atomic import NotReplaced, replace_all
from arboretum_library.errors import ArboretumError, InputError
from arboretum_library.geometry import make_transform

from .script_check import Op, Pose

if TYPE_CHECKING:
    from arboretum_library.store import Library


def posed(pose: Pose, T_world_example: np.ndarray, scale: float) -> tuple[np.ndarray, float]:
    """(rigid (4, 4) T, scale) of a placement at ``T_world_example`` and ``scale`` after ``pose``: ``T``
    replaces rotation and translation; otherwise the rotation, ``at`` and ``scale`` given replace theirs."""
    T = np.array(T_world_example if pose.T is None else pose.T, dtype=np.float64)
    if pose.R is not None:
        T[:3, :3] = pose.R
    if pose.at is not None:
        T[:3, 3] = pose.at
    return T, scale if pose.scale is None else pose.scale


def lobe_posed(pose: Pose, T_example_lobe: np.ndarray) -> np.ndarray:
    """The (4, 4) similarity of a lobe at ``T_example_lobe`` after ``pose`` (``T``: the whole of it)."""
    if pose.T is not None:
        return np.array(pose.T, dtype=np.float64)
    M = np.asarray(T_example_lobe, dtype=np.float64)
    s = float(np.cbrt(np.linalg.det(M[:3, :3])))
    R = M[:3, :3] / s if pose.R is None else pose.R
    t = M[:3, 3] if pose.at is None else pose.at
    return make_transform(R, t, s if pose.scale is None else pose.scale)


@dataclass(frozen=True)
class Staged:
    """A file written aside, waiting for ``commit``."""

    tmp: Path
    """The new file: ``.NAME.PID-N.tmp`` beside ``out``."""
    out: Path
    """Its destination, as the user named it."""
    what: str
    """What names it in an error: ``--out`` or ``operation 3 (export): out``."""


def swap(staged: list[Staged]) -> None:
    """Put every staged file in place, all or none (``atomic.replace_all``, Ctrl-C held back);
    ``InputError`` naming the destination and the problem when one cannot be replaced."""
    try:
        replace_all([(s.tmp, s.out) for s in staged])
    except NotReplaced as exc:
        failed = staged[exc.index]
        raise InputError(f"{failed.what} {failed.out}: cannot be replaced ({exc.strerror}); "
                         + (exc.lost or "no file was changed")) from None


class Runner:
    """A server context of its own (library, a session in a temporary state folder) for one script."""

    def __init__(self, library: Path, state: Path, name: str = "", start: Assembly | None = None,
                 opened: Library | None = None) -> None:
        """``opened``: the library already opened (``cli.open_library``), used instead of opening
        ``library`` (the context closes it)."""
        from arboretum_server.service.context import Context
        from arboretum_server.service.dispatch import Dispatcher
        from arboretum_server.service.sessions import Sessions

        self.ctx = Context(Sessions(state), library, _library=opened)
        self.dispatch = Dispatcher(self.ctx)
        self.depth = 0
        """Edits since the start that ``undo`` may take back."""
        self.staged: list[Staged] = []
        """The files written aside so far (each export's, ``--out``'s), in order."""
        try:
            req = P.SessionLoad(assembly=start, name=name) if start is not None else P.SessionNew(name=name)
            self.session = self._call(req).session
        except ArboretumError as exc:
            self.close()
            raise InputError(f"--from: {exc}" if start is not None else str(exc)) from None

    def _call(self, req: P.Request, progress=None) -> Any:
        reply = self.dispatch.run(req, progress)
        if isinstance(reply, P.Error):
            raise InputError(reply.message)
        return reply

    def run(self, op: Op, progress=None) -> dict:
        """Run ``op``; a JSON-able summary of what it did. Any error names the operation."""
        if op.kind == "export":
            return self._export(op, progress)
        try:
            if op.kind == "undo" and self.depth == 0:
                raise InputError("nothing to undo")
            r = self._call(self._request(op))
        except ArboretumError as exc:
            raise InputError(f"{op.where}: {exc}") from None
        self.depth += -1 if op.kind == "undo" else 1
        return {"op": op.kind, "label": r.label, "instance": r.instance, "merged": list(r.merged),
                "kinds": list(r.kinds), "revision": r.revision}

    def _request(self, op: Op) -> P.Request:
        s, a = self.session, op.args
        if op.kind == "add":
            T, scale = posed(a["pose"], np.eye(4), 1.0)
            return P.AddExample(session=s, example_id=a["example"], T_world_example=T, scale=scale,
                                instance=a["instance"])
        if op.kind == "transform":
            p = self.placement(a["instance"])
            T, scale = posed(a["pose"], p.T_world_example, p.scale)
            return P.TransformExample(session=s, instance=p.instance, T_world_example=T, scale=scale)
        if op.kind == "transform_lobe":
            p = self.placement(a["instance"])
            now = next((lt.T_example_lobe for lt in p.lobe_transforms if lt.lobe == a["lobe"]), np.eye(4))
            return P.TransformLobe(session=s, instance=p.instance, lobe=a["lobe"],
                                   T_example_lobe=lobe_posed(a["pose"], now))
        if op.kind == "sketch":
            pts, sizes = P.pack_strokes(a["strokes"])
            return P.SketchExample(session=s, stroke_points=pts, stroke_sizes=sizes, instance=a["as"])
        if op.kind == "delete":
            return P.DeleteExample(session=s, instance=a["instance"])
        return (P.Undo if op.kind == "undo" else P.Redo)(session=s)

    def placement(self, instance: str) -> Placement:
        """The session's placement ``instance`` as it is now; ``InputError`` when there is none."""
        for p in self.assembly().placements:
            if p.instance == instance:
                return p
        raise InputError(f"no placement {instance!r} in this session")

    def _export(self, op: Op, progress) -> dict:
        a = op.args
        try:
            r = self._call(P.ExportMesh(session=self.session, format=a["format"], seed=a["seed"],
                                        lod=a["lod"], options=a["options"]), progress)
        except ArboretumError as exc:
            raise InputError(f"{op.where}: {exc}") from None
        out: Path = a["out"]
        self.stage(out, f"{op.where}: out", lambda tmp: tmp.write_bytes(r.data.tobytes()))
        return {"op": "export", "label": f"exported {out} ({len(r.data)} bytes)", "out": str(out), **r.stats}

    def stage(self, out: Path, what: str, write: Callable[[Path], Any]) -> None:
        """Write ``out``'s new file aside, ``write(temporary path)``, for ``commit``; ``what`` names it in
        errors (``--out``, ``operation 3 (export): out``)."""
        tmp = out.with_name(f".{out.name}.{os.getpid()}-{len(self.staged)}.tmp")
        self.staged.append(Staged(tmp, out, what))
        try:
            write(tmp)
        except OSError as exc:
            raise InputError(f"{what} {out}: cannot write ({exc.strerror or exc})") from None

    def commit(self) -> None:
        """Put every staged file in place, all or none (``swap``), after the last operation succeeded."""
        staged, self.staged = self.staged, []
        swap(staged)  # on a failure, it removes the temporary files itself

    def assembly(self) -> Assembly:
        return self._call(P.SessionGet(session=self.session)).assembly

    def close(self) -> None:
        """Remove the files of exports not committed; close the library."""
        for s in self.staged:
            s.tmp.unlink(missing_ok=True)
        self.staged = []
        self.ctx.close()
