"""The only GL code of the client: shader programs, GPU buffers, textures and the renderer.

``renderer.Renderer`` draws a ``scene.Scene`` seen by a ``camera.Camera`` into its own framebuffer
(MSAA, or 2x supersampling where MSAA is missing) and renders an integer ID buffer for picking.
``meshes`` holds the CPU geometry (tubes, normals, primitives) in numpy; ``programs`` loads the
GLSL 3.3 core shaders shipped under ``shaders/``; ``buffers`` turns scene items into draw batches;
``textures`` uploads and caches images (with cut-out-aware mipmaps); ``layers`` draws billboards
and the 2D UI image.
"""
