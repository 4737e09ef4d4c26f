#version 330 core
// Line segments (pairs of vertices), widened to screen-space quads by lines.geom.
//#include transform.glsl
in vec4 in_color;
out vec4 g_color;
flat out int g_id;
void main() {
    g_color = in_color;
    g_id = in_id;
    gl_Position = clip_from_world(in_pos);
}
