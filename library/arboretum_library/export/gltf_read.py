"""A minimal reader of binary glTF 2.0 (GLB): triangle meshes, their materials and where they are placed.

Reads what Arboretum writes (``gltf.py``, ``instanced.py``) and similar files: the GLB header, JSON and
BIN chunks; accessors (float, unsigned and signed integers, normalised where flagged, strided views);
triangle primitives with or without indices; base colour factor and embedded textures; node matrices
or TRS composed down the scene graph; ``EXT_mesh_gpu_instancing``. glTF is Y up, the world Z up: all
positions, normals and transforms go through ``geometry.yup_to_zup``. Every primitive becomes one
``GltfMesh`` holding all its placements, so nodes sharing a mesh read back as instances of one mesh.
numpy and the standard library only; a malformed file raises one ``InputError`` naming it.
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from arboretum_library.errors import InputError
from arboretum_library.geometry import yup_to_zup

COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
INSTANCING = "EXT_mesh_gpu_instancing"
D_ZUP_YUP = np.eye(4)
D_ZUP_YUP[:3, :3] = yup_to_zup(np.eye(3)).T
"""4x4 rotation taking glTF (Y up) coordinates to the world (Z up): the matrix of ``yup_to_zup``."""


@dataclass(frozen=True, eq=False)
class GltfMesh:
    """One triangle primitive of a GLB with its material and every placement of it."""

    name: str
    """The glTF mesh's name (with '#k' for its k-th primitive after the first)."""
    positions: np.ndarray
    """(V, 3) float64, the mesh's own frame converted to Z up."""
    normals: np.ndarray | None
    """(V, 3) float64 Z up, or None."""
    uvs: np.ndarray | None
    """(V, 2) float64 TEXCOORD_0 (v = 0 at the image's top), or None."""
    faces: np.ndarray
    """(F, 3) int32 indices into ``positions``."""
    base_color: np.ndarray
    """(4,) float64 linear RGBA baseColorFactor."""
    texture: bytes | None
    """The embedded base colour image (PNG or JPEG bytes), or None."""
    alpha_mode: str
    """'OPAQUE', 'MASK' or 'BLEND'."""
    double_sided: bool
    """The material's doubleSided flag."""
    instances: np.ndarray
    """(K, 4, 4) float64 world (Z up) transforms from the mesh's frame, one per placement (K >= 1)."""


def read_glb(path: str | os.PathLike) -> list[GltfMesh]:
    """Every placed triangle primitive of the GLB file ``path`` (InputError when it is malformed)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    return parse_glb(data, str(path))


def parse_glb(data: bytes, name: str = "GLB") -> list[GltfMesh]:
    """``read_glb`` over bytes; ``name`` is used in error messages."""
    doc, blob = _chunks(data, name)
    try:
        return _Reader(doc, blob, name).meshes()
    except InputError:
        raise
    except KeyError as exc:
        raise InputError(f"{name}: malformed glTF JSON (missing property {exc})") from None
    except IndexError:
        raise InputError(f"{name}: malformed glTF JSON (an index refers to a missing entry)") from None
    except (TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{name}: malformed glTF JSON ({exc})") from None


def _chunks(data: bytes, name: str) -> tuple[dict[str, Any], bytes]:
    """The JSON document and the BIN chunk (b'' when absent) of GLB ``data``."""
    if len(data) < 12:
        raise InputError(f"{name}: too short for a GLB header ({len(data)} bytes)")
    magic, version, length = struct.unpack_from("<4sII", data)
    if magic != b"glTF":
        raise InputError(f"{name}: not a GLB file (magic {magic!r}, expected b'glTF')")
    if version != 2:
        raise InputError(f"{name}: GLB version {version}; only glTF 2.0 is supported")
    if length > len(data):
        raise InputError(f"{name}: truncated: header says {length} bytes, file has {len(data)}")
    chunks, at = [], 12
    while at + 8 <= length:
        size, kind = struct.unpack_from("<I4s", data, at)
        if at + 8 + size > length:
            raise InputError(f"{name}: truncated {kind!r} chunk ({size} bytes at offset {at + 8}, "
                             f"file ends at {length})")
        chunks.append((kind, data[at + 8:at + 8 + size]))
        at += 8 + size
    if not chunks or chunks[0][0] != b"JSON":
        raise InputError(f"{name}: the first GLB chunk must be JSON")
    try:
        doc = json.loads(chunks[0][1])
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{name}: the JSON chunk is not valid JSON ({exc})") from None
    asset = doc.get("asset") if isinstance(doc, dict) else None
    if not isinstance(asset, dict) or str(asset.get("version", "")).split(".")[0] != "2":
        raise InputError(f"{name}: not a glTF 2.0 document (asset.version missing or not 2.x)")
    blob = next((c for k, c in chunks[1:] if k == b"BIN\x00"), b"")
    return doc, blob


def _trs(node: dict[str, Any]) -> np.ndarray:
    """A node's local 4x4 transform (column vectors, glTF frame) from ``matrix`` or T * R * S."""
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T
    t = np.asarray(node.get("translation", (0.0, 0.0, 0.0)), np.float64).reshape(1, 3)
    q = np.asarray(node.get("rotation", (0.0, 0.0, 0.0, 1.0)), np.float64).reshape(1, 4)
    s = np.asarray(node.get("scale", (1.0, 1.0, 1.0)), np.float64).reshape(1, 3)
    return trs_matrices(t, q, s)[0]


def trs_matrices(t: np.ndarray, q_xyzw: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(K, 4, 4) transforms T * R * S from translations (K, 3), unit quaternions xyzw (K, 4), scales (K, 3)."""
    q = q_xyzw / np.maximum(np.linalg.norm(q_xyzw, axis=1, keepdims=True), 1e-300)
    x, y, z, w = q.T
    R = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1).reshape(-1, 3, 3)
    M = np.tile(np.eye(4), (len(t), 1, 1))
    M[:, :3, :3] = R * s[:, None, :]
    M[:, :3, 3] = t
    return M


class _Reader:
    """Decodes one parsed document; ``meshes()`` is the result."""

    def __init__(self, doc: dict[str, Any], blob: bytes, name: str) -> None:
        self.doc, self.blob, self.name = doc, blob, name
        self.placements: dict[int, list[np.ndarray]] = {}
        """glTF mesh index -> world (Y up) transforms (each (K, 4, 4)) of the nodes using it."""

    def fail(self, problem: str) -> InputError:
        return InputError(f"{self.name}: {problem}")

    def accessor(self, index: int) -> np.ndarray:
        """(count, width) float64 or integer values of accessor ``index``."""
        acc = self.doc["accessors"][index]
        if "sparse" in acc:
            raise self.fail(f"accessor {index} is sparse; sparse accessors are not supported")
        dtype = COMPONENTS.get(acc["componentType"])
        width = WIDTHS.get(acc["type"])
        if dtype is None or width is None:
            raise self.fail(f"accessor {index}: componentType {acc['componentType']} / type "
                            f"{acc['type']!r} is not supported")
        count, item = int(acc["count"]), np.dtype(dtype).itemsize
        if "bufferView" not in acc:
            return np.zeros((count, width), dtype)
        view = self.doc["bufferViews"][acc["bufferView"]]
        if view.get("buffer", 0) != 0 or "uri" in self.doc["buffers"][view.get("buffer", 0)]:
            raise self.fail(f"accessor {index} uses an external buffer; only the GLB's BIN chunk is read")
        stride = int(view.get("byteStride", width * item))
        start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
        end = start + (count - 1) * stride + width * item if count else start
        view_end = int(view.get("byteOffset", 0)) + int(view["byteLength"])
        if end > view_end or view_end > len(self.blob) or stride < width * item:
            raise self.fail(f"accessor {index} out of range: needs bytes {start}..{end} of bufferView "
                            f"{acc['bufferView']} (ends at {view_end}; BIN chunk has {len(self.blob)} bytes)")
        out = np.ndarray((count, width), np.dtype(dtype).newbyteorder("<"), self.blob, start, (stride, item))
        if acc.get("normalized") and out.dtype.kind in "iu":
            info = np.iinfo(dtype)
            return np.maximum(out / float(info.max), -1.0)
        return out.copy()

    def walk(self, index: int, parent: np.ndarray, seen: frozenset[int]) -> None:
        """Record the world transforms of node ``index`` (and its children) under ``parent``."""
        if index in seen:
            raise self.fail(f"node {index} is its own ancestor (the node graph has a cycle)")
        node = self.doc["nodes"][index]
        world = parent @ _trs(node)
        if "mesh" in node:
            inst = node.get("extensions", {}).get(INSTANCING)
            local = self.instance_matrices(inst["attributes"]) if inst else np.eye(4)[None]
            self.placements.setdefault(int(node["mesh"]), []).append(world @ local)
        for child in node.get("children", []):
            self.walk(int(child), world, seen | {index})

    def instance_matrices(self, attrs: dict[str, int]) -> np.ndarray:
        """(K, 4, 4) per-instance transforms of an ``EXT_mesh_gpu_instancing`` node (glTF frame)."""
        cols = {k: self.accessor(v).astype(np.float64) for k, v in attrs.items()
                if k in ("TRANSLATION", "ROTATION", "SCALE")}
        counts = {len(v) for v in cols.values()}
        if len(counts) != 1:
            raise self.fail(f"{INSTANCING}: attributes have different counts {sorted(counts)}")
        k = counts.pop()
        t = cols.get("TRANSLATION", np.zeros((k, 3)))
        q = cols.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (k, 1)))
        s = cols.get("SCALE", np.ones((k, 3)))
        return trs_matrices(t, q, s)

    def material(self, index: int | None) -> tuple[np.ndarray, bytes | None, str, bool]:
        """Base colour (4,), texture bytes or None, alpha mode and double-sidedness of a material."""
        if index is None:
            return np.ones(4), None, "OPAQUE", False
        mat = self.doc["materials"][index]
        pbr = mat.get("pbrMetallicRoughness", {})
        texture = None
        if "baseColorTexture" in pbr:
            source = self.doc["textures"][pbr["baseColorTexture"]["index"]].get("source")
            image = self.doc["images"][source] if source is not None else {}
            if "bufferView" in image:  # images by URI are not read: the base colour factor alone is used
                view = self.doc["bufferViews"][image["bufferView"]]
                start = int(view.get("byteOffset", 0))
                if start + int(view["byteLength"]) > len(self.blob):
                    raise self.fail(f"image bufferView {image['bufferView']} runs past the BIN chunk")
                texture = self.blob[start:start + int(view["byteLength"])]
        color = np.asarray(pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0)), np.float64).reshape(4)
        return color, texture, str(mat.get("alphaMode", "OPAQUE")), bool(mat.get("doubleSided", False))

    def primitive(self, name: str, prim: dict[str, Any], world_yup: np.ndarray) -> GltfMesh:
        """A ``GltfMesh`` of one primitive placed by ``world_yup`` (K, 4, 4)."""
        if prim.get("mode", 4) != 4:
            raise self.fail(f"mesh {name!r}: primitive mode {prim['mode']} (only triangles, mode 4, are read)")
        attrs = prim["attributes"]
        pos = self.accessor(attrs["POSITION"]).astype(np.float64)
        if "indices" in prim:
            idx = self.accessor(prim["indices"]).reshape(-1).astype(np.int64)
        else:
            idx = np.arange(len(pos))
        if len(idx) % 3 or (len(idx) and (idx.min() < 0 or idx.max() >= len(pos))):
            raise self.fail(f"mesh {name!r}: {len(idx)} indices are not triangles into {len(pos)} vertices")
        normals = yup_to_zup(self.accessor(attrs["NORMAL"]).astype(np.float64)) if "NORMAL" in attrs else None
        uvs = self.accessor(attrs["TEXCOORD_0"]).astype(np.float64) if "TEXCOORD_0" in attrs else None
        color, texture, alpha, double = self.material(prim.get("material"))
        instances = D_ZUP_YUP @ world_yup @ D_ZUP_YUP.T
        return GltfMesh(name, yup_to_zup(pos), normals, uvs, idx.reshape(-1, 3).astype(np.int32), color,
                        texture, alpha, double, instances)

    def meshes(self) -> list[GltfMesh]:
        doc = self.doc
        scenes = doc.get("scenes", [])
        if scenes:
            roots = scenes[int(doc.get("scene", 0))].get("nodes", [])
        else:
            children = {c for n in doc.get("nodes", []) for c in n.get("children", [])}
            roots = [i for i in range(len(doc.get("nodes", []))) if i not in children]
        for root in roots:
            self.walk(int(root), np.eye(4), frozenset())
        out = []
        for m, placements in sorted(self.placements.items()):
            mesh = doc["meshes"][m]
            world = np.concatenate(placements)
            for k, prim in enumerate(mesh["primitives"]):
                name = mesh.get("name", f"mesh{m}") + (f"#{k}" if k else "")
                out.append(self.primitive(name, prim, world))
        return out
