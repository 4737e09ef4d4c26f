#version 330 core
// A full-screen triangle from gl_VertexID (no vertex buffer).
out float v_t;
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));
    v_t = 0.5 + 0.5 * p.y;
    gl_Position = vec4(p, 0.0, 1.0);
}
