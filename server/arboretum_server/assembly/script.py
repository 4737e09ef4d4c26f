"""Run a checked assembly script (``script_check.Op``) through the service's handlers, in this process.

Three rules on top of the handlers, for a pipeline that runs a script and trusts its files:

- ``transform`` and ``transform_lobe`` change only the keys they give: ``at``, the rotation
  (``rotate`` / ``rotate_z``) and ``scale`` each keep the instance's (or the lobe's) current value
  when left out, read from the session as the operation runs;
- the session an ``undo`` can go back to is the one the script started from: undoing the loading of a
  ``--from`` session is "nothing to undo", as in a fresh script;
- an export writes its file beside its destination under a hidden temporary name; ``commit`` renames
  every such file into place once all operations succeeded (Ctrl-C held back until the last rename),
  and ``close`` removes those left, so a script that fails (or is interrupted) leaves no export behind.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.assembly import Assembly, Placement
from arboretum_library.atomic import interruptible
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
        self.staged: list[tuple[Path, Path]] = []
        """(temporary file, destination) of each export run so far."""
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
        try:
            if op.kind == "export":
                return self._export(op.args, progress)
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

    def _export(self, a: dict, progress) -> dict:
        req = P.ExportMesh(session=self.session, format=a["format"], seed=a["seed"], lod=a["lod"],
                           options=a["options"])
        r = self._call(req, progress)
        out: Path = a["out"]
        tmp = out.with_name(f".{out.name}.{os.getpid()}-{len(self.staged)}.tmp")
        try:
            with open(tmp, "wb") as f:
                self.staged.append((tmp, out))
                f.write(r.data.tobytes())
        except OSError as exc:
            raise InputError(f"out {out}: cannot write ({exc.strerror})") from None
        return {"op": "export", "label": f"exported {out} ({len(r.data)} bytes)", "out": str(out), **r.stats}

    def commit(self) -> None:
        """Move every export's file into place (after the last operation succeeded), Ctrl-C held back
        until the last one (``atomic.interruptible``; the caller may hold it over more, e.g. ``--out``)."""
        with interruptible():
            while self.staged:
                tmp, out = self.staged[0]
                os.replace(tmp, out)
                self.staged.pop(0)

    def assembly(self) -> Assembly:
        return self._call(P.SessionGet(session=self.session)).assembly

    def close(self) -> None:
        """Remove the files of exports not committed; close the library."""
        for tmp, _ in self.staged:
            tmp.unlink(missing_ok=True)
        self.staged = []
        self.ctx.close()
