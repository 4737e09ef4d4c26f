"""Shader programs: GLSL 3.3 core sources shipped as package data (``render/shaders/*.glsl``, read
with importlib.resources), each compiled twice: for colour and, with ``#define PICK``, for the integer
ID buffer used by picking. GLSL has no includes, so a line ``//#include NAME`` in a source is replaced
by the text of ``shaders/NAME`` (code several shaders share: outputs, highlight, transform).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import moderngl
import numpy as np

PROGRAMS: dict[str, tuple[str, ...]] = {
    "lit": ("lit.vert.glsl", "lit.frag.glsl"),
    "instanced": ("instanced.vert.glsl", "lit.frag.glsl"),
    "textured": ("lit.vert.glsl", "lit.frag.glsl"),
    "textured_instanced": ("instanced.vert.glsl", "lit.frag.glsl"),
    "points": ("points.vert.glsl", "points.frag.glsl"),
    "lines": ("lines.vert.glsl", "lines.geom.glsl", "flat.frag.glsl"),
    "background": ("background.vert.glsl", "background.frag.glsl"),
    "ui": ("ui.vert.glsl", "ui.frag.glsl"),
    "billboard": ("billboard.vert.glsl", "billboard.frag.glsl"),
}
"""Program name -> (vertex, [geometry,] fragment) shader file names."""

DEFINES: dict[str, tuple[str, ...]] = {"textured": ("TEXTURED",), "textured_instanced": ("TEXTURED",)}
"""Program name -> preprocessor symbols it is compiled with (one source, several variants)."""

PICKABLE = ("lit", "instanced", "textured", "textured_instanced", "points", "lines")


INCLUDE = "//#include "
"""A source line starting with this is replaced by the shader file it names."""


def shader_source(name: str, defines: tuple[str, ...] = ()) -> str:
    """The text of shader ``name``, includes expanded, with ``#define`` lines inserted after its
    ``#version`` line."""
    text = expand_includes(_read(name), (name,))
    head, _, rest = text.partition("\n")
    return "\n".join([head, *(f"#define {d}" for d in defines), rest])


def expand_includes(text: str, chain: tuple[str, ...] = ()) -> str:
    """``text`` with every ``//#include NAME`` line replaced by the (expanded) text of ``shaders/NAME``;
    ``chain`` names the files being expanded, to refuse an include cycle."""
    lines = []
    for line in text.splitlines():
        if not line.startswith(INCLUDE):
            lines.append(line)
            continue
        name = line[len(INCLUDE):].strip()
        if name in chain:
            raise ValueError(f"shader include cycle: {' -> '.join([*chain, name])}")
        lines.append(expand_includes(_read(name), (*chain, name)).rstrip("\n"))
    return "\n".join(lines) + "\n"


def _read(name: str) -> str:
    return resources.files("arboretum_client.render").joinpath("shaders", name).read_text()


def build_program(ctx: moderngl.Context, name: str, pick: bool = False) -> moderngl.Program:
    """Compile program ``name`` (a key of ``PROGRAMS``); ``pick`` selects the ID-buffer variant."""
    files = PROGRAMS[name]
    defines = DEFINES.get(name, ()) + (("PICK",) if pick else ())
    return ctx.program(vertex_shader=shader_source(files[0], defines),
                       fragment_shader=shader_source(files[-1], defines),
                       geometry_shader=shader_source(files[1], defines) if len(files) == 3 else None)


@dataclass
class Programs:
    """Every program, compiled once per context."""

    color: dict[str, moderngl.Program]
    pick: dict[str, moderngl.Program]

    @classmethod
    def build(cls, ctx: moderngl.Context) -> Programs:
        return cls(color={n: build_program(ctx, n) for n in PROGRAMS},
                   pick={n: build_program(ctx, n, pick=True) for n in PICKABLE})

    def release(self) -> None:
        for p in [*self.color.values(), *self.pick.values()]:
            p.release()


def set_uniforms(prog: moderngl.Program, **values) -> None:
    """Set each uniform that ``prog`` uses; 4x4 numpy matrices are sent column-major."""
    for key, value in values.items():
        if key not in prog:
            continue
        uniform = prog[key]
        assert isinstance(uniform, moderngl.Uniform), f"{key} is not a uniform"
        arr = np.asarray(value, dtype=np.float32)
        if arr.shape == (4, 4):
            uniform.write(np.ascontiguousarray(arr.T).tobytes())
        elif arr.ndim == 0:
            uniform.value = float(arr)
        else:
            uniform.value = tuple(float(x) for x in arr)
