#version 330 core
// Line segments (pairs of vertices), widened to screen-space quads by lines.geom.
uniform mat4 u_view_proj;
in vec3 in_pos;
in vec4 in_color;
in int in_id;
out vec4 g_color;
flat out int g_id;
void main() {
    g_color = in_color;
    g_id = in_id;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
}
