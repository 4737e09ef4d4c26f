"""Run assembly-script operations through the service's handlers, in this process (no socket)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from arboretum_library import protocol as P
from arboretum_library.errors import InputError
from arboretum_library.geometry import axis_angle_matrix, make_transform
from arboretum_library.model import Assembly


def transform(spec: dict, where: str) -> tuple[np.ndarray, float]:
    """(4x4 rigid T, uniform scale) from ``T`` or ``at`` / ``rotate`` / ``rotate_z`` / ``scale``."""
    try:
        scale = float(spec.get("scale", 1.0))
        if "T" in spec:
            return np.asarray(spec["T"], dtype=np.float64).reshape(4, 4), scale
        R = np.eye(3)
        if "rotate" in spec:
            *axis, deg = (float(x) for x in spec["rotate"])
            R = axis_angle_matrix(np.array(axis), np.radians(deg))
        elif "rotate_z" in spec:
            R = axis_angle_matrix(np.array([0.0, 0, 1]), np.radians(float(spec["rotate_z"])))
        at = np.asarray(spec.get("at", [0, 0, 0]), dtype=np.float64).reshape(3)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: bad transform ({exc})") from None
    return make_transform(R, at), scale


class Runner:
    """A server context of its own (library, a session in a temporary state folder) for one script."""

    def __init__(self, library: Path, state: Path, name: str = "", start: Assembly | None = None) -> None:
        from arboretum_server.service.context import Context
        from arboretum_server.service.dispatch import Dispatcher
        from arboretum_server.service.sessions import Sessions

        self.ctx = Context(Sessions(state), library)
        self.dispatch = Dispatcher(self.ctx)
        req = P.SessionLoad(assembly=start, name=name) if start is not None else P.SessionNew(name=name)
        self.session = self._call(req, "session").session

    def _call(self, req: P.Request, where: str, progress=None) -> Any:
        reply = self.dispatch.run(req, progress)
        if isinstance(reply, P.Error):
            raise InputError(f"{where}: {reply.message}")
        return reply

    def run(self, i: int, op: dict, progress=None) -> dict:
        """Run operation number ``i``; a JSON-able summary of what it did."""
        (kind, spec), = op.items()
        where = f"operation {i + 1} ({kind})"
        spec = spec or {}
        if not isinstance(spec, dict):
            raise InputError(f"{where}: its arguments must be a map")
        if kind == "export":
            return self._export(spec, where, progress)
        req = self._request(kind, spec, where)
        r = self._call(req, where)
        return {"op": kind, "label": r.label, "instance": r.instance, "merged": list(r.merged),
                "kinds": list(r.kinds), "revision": r.revision}

    def _request(self, kind: str, spec: dict, where: str) -> P.Request:
        s = self.session
        try:
            if kind == "add":
                T, scale = transform(spec, where)
                return P.AddExample(session=s, example_id=str(spec["example"]), T_world_example=T, scale=scale,
                                    instance=str(spec.get("as", "")))
            if kind == "transform":
                T, scale = transform(spec, where)
                return P.TransformExample(session=s, instance=str(spec["instance"]), T_world_example=T, scale=scale)
            if kind == "transform_lobe":
                T, scale = transform(spec, where)
                T[:3, :3] *= scale
                return P.TransformLobe(session=s, instance=str(spec["instance"]), lobe=int(spec["lobe"]), T_example_lobe=T)
            if kind == "sketch":
                pts, sizes = P.pack_strokes([np.asarray(st, dtype=np.float64) for st in spec["strokes"]])
                return P.SketchExample(session=s, stroke_points=pts, stroke_sizes=sizes, instance=str(spec.get("as", "")))
            if kind == "delete":
                return P.DeleteExample(session=s, instance=str(spec["instance"]))
            if kind in ("undo", "redo"):
                return (P.Undo if kind == "undo" else P.Redo)(session=s)
        except KeyError as exc:
            raise InputError(f"{where}: missing argument {exc}") from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: {exc}") from None
        raise InputError(f"{where}: unknown operation (use add, transform, transform_lobe, sketch, delete, undo, redo, export)")

    def _export(self, spec: dict, where: str, progress) -> dict:
        if "out" not in spec:
            raise InputError(f"{where}: missing argument 'out'")
        out = Path(str(spec["out"]))
        fmt = out.suffix.lower().lstrip(".")
        req = P.ExportMesh(session=self.session, format=fmt, seed=int(spec.get("seed", 0)),
                           lod=int(spec.get("lod", 0)), options=dict(spec.get("options", {})))
        r = self._call(req, where, progress)
        name = out.with_suffix(".zip") if fmt == "obj" else out
        tmp = name.with_name(f".{name.name}.tmp")
        tmp.write_bytes(r.data.tobytes())
        tmp.replace(name)
        return {"op": "export", "label": f"exported {name} ({len(r.data)} bytes)", "out": str(name), **r.stats}

    def assembly(self) -> Assembly:
        return self._call(P.SessionGet(session=self.session), "session").assembly

    def close(self) -> None:
        self.ctx.close()
