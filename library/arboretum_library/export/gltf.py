"""A binary glTF 2.0 (GLB) writer over plain arrays: meshes, materials, embedded PNG textures, nodes.

The world is Z up; glTF is Y up, so positions and normals go through ``geometry.zup_to_yup`` and node
matrices through the same change of basis. Nodes that share a mesh are written as plain nodes (every
importer reads them); no extension is needed. Meshes given in the world frame of a scene far from the
origin (``parts.local_origin``), or nodes placed far from it, are written relative to it under a root node
"origin" whose translation (JSON, float64) puts them back. numpy and the standard library only.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np

from arboretum_library.atomic import write_atomic
from arboretum_library.geometry import zup_to_yup

from .parts import Material, MeshPart, Node, local_origin

FLOAT, UINT16, UINT32 = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
C_YUP_ZUP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
"""Rotation taking world (Z up) vectors to glTF (Y up): (x, y, z) -> (x, z, -y)."""


class _Builder:
    """Collects the JSON document and the binary chunk."""

    def __init__(self) -> None:
        self.doc: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": "arboretum"},
            "buffers": [], "bufferViews": [], "accessors": [], "meshes": [], "materials": [],
            "nodes": [], "scenes": [{"nodes": []}], "scene": 0,
        }
        self.blob = bytearray()

    def view(self, data: bytes, target: int | None = None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.blob.extend(data)
        self.doc["bufferViews"].append(view)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, arr: np.ndarray, kind: str, target: int | None, minmax: bool = False) -> int:
        if arr.dtype == np.float32:
            ctype = FLOAT
        elif arr.dtype == np.uint16:
            ctype = UINT16
        else:
            ctype = UINT32
        acc: dict[str, Any] = {
            "bufferView": self.view(np.ascontiguousarray(arr).tobytes(), target),
            "componentType": ctype, "count": int(len(arr)), "type": kind,
        }
        if minmax:
            acc["min"] = [float(x) for x in arr.min(0)]
            acc["max"] = [float(x) for x in arr.max(0)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1


def _primitive(b: _Builder, part: MeshPart, origin: np.ndarray | None = None) -> dict[str, Any]:
    """The primitive of ``part``, its positions relative to ``origin`` (3,) (world, Z up) if given."""
    pos = part.positions if origin is None or not origin.any() else part.positions - origin
    pos = zup_to_yup(pos).astype(np.float32)
    attrs = {"POSITION": b.accessor(pos, "VEC3", ARRAY_BUFFER, minmax=True)}
    if part.normals is not None:
        nrm = zup_to_yup(np.asarray(part.normals, np.float64))
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
        attrs["NORMAL"] = b.accessor(nrm.astype(np.float32), "VEC3", ARRAY_BUFFER)
    if part.uv is not None:
        attrs["TEXCOORD_0"] = b.accessor(np.asarray(part.uv, np.float32), "VEC2", ARRAY_BUFFER)
    idx_type = np.uint16 if len(pos) < 65535 else np.uint32
    idx = part.faces.astype(idx_type).reshape(-1)
    prim = {"attributes": attrs, "indices": b.accessor(idx, "SCALAR", ELEMENT_ARRAY_BUFFER), "mode": 4}
    prim["material"] = int(part.material)
    return prim


def _materials(b: _Builder, materials: Sequence[Material]) -> None:
    images: dict[bytes, int] = {}
    for m in materials:
        pbr: dict[str, Any] = {"baseColorFactor": [float(c) for c in m.base_color],
                               "metallicFactor": float(m.metallic), "roughnessFactor": float(m.roughness)}
        if m.texture_png is not None:
            if m.texture_png not in images:
                view = b.view(m.texture_png)
                b.doc.setdefault("images", []).append({"bufferView": view, "mimeType": "image/png"})
                b.doc.setdefault("textures", []).append({"source": len(b.doc["images"]) - 1, "sampler": 0})
                images[m.texture_png] = len(b.doc["textures"]) - 1
            pbr["baseColorTexture"] = {"index": images[m.texture_png]}
        mat: dict[str, Any] = {"name": m.name, "pbrMetallicRoughness": pbr, "doubleSided": bool(m.double_sided)}
        if m.alpha_cutoff is not None:
            mat["alphaMode"] = "MASK"
            mat["alphaCutoff"] = float(m.alpha_cutoff)
        b.doc["materials"].append(mat)
    if images:
        b.doc["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]


def node_matrix_yup(T_world_node: np.ndarray) -> list[float]:
    """Column-major glTF matrix (16,) of a world (Z up) 4x4 transform expressed in the Y-up frame."""
    C = np.eye(4)
    C[:3, :3] = C_YUP_ZUP
    M = C @ np.asarray(T_world_node, np.float64) @ C.T
    return [float(x) for x in M.T.reshape(-1)]


def glb_bytes(meshes: Sequence[MeshPart], materials: Sequence[Material],
              nodes: Sequence[Node] | None = None) -> bytes:
    """The bytes of a GLB holding ``meshes`` (empty ones are skipped) placed by ``nodes``.

    ``nodes`` defaults to one untransformed node per mesh (meshes in the world frame). A far scene is
    written relative to ``local_origin`` (see the module docs): of the mesh positions without ``nodes``,
    of the node translations with them (each node's matrix then carries its translation minus it).
    Node ``mesh`` indices refer to ``meshes``.
    """
    b = _Builder()
    _materials(b, materials)
    if not b.doc["materials"]:
        del b.doc["materials"]
    if nodes is None:
        used = [m.positions for m in meshes if len(m.faces)]
        origin = local_origin(np.concatenate(used) if used else np.zeros((0, 3)))
        nodes, mesh_origin = [Node(i, name=m.name) for i, m in enumerate(meshes)], origin
    else:
        placed = [n.T_world_node[:3, 3] for n in nodes
                  if 0 <= n.mesh < len(meshes) and len(meshes[n.mesh].faces)]
        origin, mesh_origin = local_origin(np.array(placed, np.float64).reshape(-1, 3)), None
    written: dict[int, int] = {}
    for i, part in enumerate(meshes):
        if len(part.faces) == 0:
            continue
        b.doc["meshes"].append({"name": part.name, "primitives": [_primitive(b, part, mesh_origin)]})
        written[i] = len(b.doc["meshes"]) - 1
    for node in nodes:
        if node.mesh not in written:
            continue
        entry: dict[str, Any] = {"mesh": written[node.mesh], "name": node.name or meshes[node.mesh].name}
        T = np.array(node.T_world_node, np.float64)
        if mesh_origin is None:
            T[:3, 3] -= origin
        if not np.allclose(T, np.eye(4)):
            entry["matrix"] = node_matrix_yup(T)
        b.doc["nodes"].append(entry)
        b.doc["scenes"][0]["nodes"].append(len(b.doc["nodes"]) - 1)
    root_at(b, origin)
    return pack_glb(b)


def root_at(b: _Builder, origin: np.ndarray) -> None:
    """Put the scene's top nodes under a new root node "origin" translated to ``origin`` (3,) (world,
    Z up; written Y up as float64 JSON); nothing when ``origin`` is zero."""
    top = b.doc["scenes"][0]["nodes"]
    if not origin.any() or not top:
        return
    b.doc["nodes"].append({"name": "origin", "translation": [float(x) for x in C_YUP_ZUP @ origin],
                           "children": list(top)})
    b.doc["scenes"][0]["nodes"] = [len(b.doc["nodes"]) - 1]


def pack_glb(b: _Builder) -> bytes:
    """The GLB bytes of a finished builder (empty lists dropped, chunks padded to 4 bytes)."""
    while len(b.blob) % 4:
        b.blob.append(0)
    if b.blob:
        b.doc["buffers"].append({"byteLength": len(b.blob)})
    if not b.doc["scenes"][0]["nodes"]:
        del b.doc["scenes"][0]["nodes"]
    for key in [k for k, v in b.doc.items() if isinstance(v, list) and not v]:
        del b.doc[key]
    js = json.dumps(b.doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + (8 + len(b.blob) if b.blob else 0)
    out = bytearray(struct.pack("<4sII", b"glTF", 2, total))
    out += struct.pack("<I4s", len(js), b"JSON") + js
    if b.blob:
        out += struct.pack("<I4s", len(b.blob), b"BIN\x00") + bytes(b.blob)
    return bytes(out)


def write_glb(path: str | os.PathLike, meshes: Sequence[MeshPart], materials: Sequence[Material],
              nodes: Sequence[Node] | None = None) -> int:
    """Write a GLB file atomically; returns its size in bytes."""
    data = glb_bytes(meshes, materials, nodes)
    write_atomic(path, data)
    return len(data)
