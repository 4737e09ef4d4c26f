#version 330 core
// A full-screen triangle carrying texture coordinates for the 2D user-interface layer.
out vec2 v_uv;
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));
    v_uv = vec2(0.5 + 0.5 * p.x, 0.5 - 0.5 * p.y);
    gl_Position = vec4(p, 0.0, 1.0);
}
