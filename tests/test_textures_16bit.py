"""16-bit (and float) grayscale images keep their levels on the way to 8-bit RGBA: textures embedded in
a GLB (decoded and mean colour) and reference images alike (Pillow's own convert clips them to white)."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from arboretum_client import app
from arboretum_client.scene import Mesh
from arboretum_client.scene_build import decode_texture, glb_items, texture_mean_color, to_rgba8
from arboretum_library.export.gltf import glb_bytes
from arboretum_library.export.gltf_read import parse_glb
from arboretum_library.export.parts import Material, MeshPart

LEVELS8 = np.array([[0, 64], [127, 255]], np.uint8)
"""The 8-bit levels of the test images; the 16-bit images hold 257 times these (exact 8-bit levels)."""


def png16(levels16: np.ndarray) -> bytes:
    """PNG bytes of a 16-bit grayscale image (Pillow opens it as mode I)."""
    buf = io.BytesIO()
    Image.fromarray(np.asarray(levels16, np.uint16)).save(buf, format="PNG")
    return buf.getvalue()


def test_a_16bit_png_texture_decodes_to_its_8bit_levels_opaque_and_read_only():
    data = png16(LEVELS8.astype(np.uint16) * 257)
    with Image.open(io.BytesIO(data)) as im:
        assert im.mode.startswith("I")  # the case Pillow's convert("RGBA") gets wrong
    rgba = decode_texture(data)
    assert rgba.shape == (2, 2, 4) and rgba.dtype == np.uint8 and not rgba.flags.writeable
    for c in range(3):
        np.testing.assert_array_equal(rgba[..., c], LEVELS8)
    np.testing.assert_array_equal(rgba[..., 3], 255)


def test_a_16bit_mid_grey_texture_has_a_mid_grey_mean_colour():
    data = png16(np.full((8, 8), 127 * 257, np.uint16))
    np.testing.assert_allclose(texture_mean_color(data), [127 / 255] * 3)


def test_a_16bit_texture_in_a_glb_draws_mid_grey_flat_and_textured():
    quad = MeshPart("leaf", np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], float),
                    np.array([[0, 1, 2], [0, 2, 3]]), uv=np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float))
    texture = png16(np.full((4, 4), 127 * 257, np.uint16))
    meshes = parse_glb(glb_bytes([quad], [Material("grey", texture_png=texture)]))
    (flat,), _ = glb_items(meshes)
    assert isinstance(flat, Mesh)
    np.testing.assert_allclose(flat.color[:3], [127 / 255] * 3, atol=1e-6)
    (textured,), _ = glb_items(meshes, textures=True)
    assert textured.texture.shape == (4, 4, 4)
    np.testing.assert_array_equal(textured.texture[..., :3], 127)


def test_8bit_rgba_and_float_images_convert_as_before():
    rgba = np.array([[[10, 20, 30, 40], [250, 128, 0, 255]]], np.uint8)
    np.testing.assert_array_equal(to_rgba8(Image.fromarray(rgba, "RGBA")), rgba)
    unit = to_rgba8(Image.fromarray(np.array([[0.0, 0.5, 1.0]], np.float32), "F"))
    np.testing.assert_array_equal(unit[0, :, 0], [0, 128, 255])
    wide = to_rgba8(Image.fromarray(np.array([[3.0, 300.0]], np.float32), "F"))
    np.testing.assert_array_equal(wide[0, :, 0], [3, 255])


def test_reference_images_use_the_same_conversion(tmp_path):
    assert app.to_rgba8 is to_rgba8
    path = tmp_path / "ref16.png"
    path.write_bytes(png16(LEVELS8.astype(np.uint16) * 257))
    np.testing.assert_array_equal(app.load_reference(path)[..., 1], LEVELS8)
