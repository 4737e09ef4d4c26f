#version 330 core
// Round screen-space dots of a fixed size in pixels.
uniform mat4 u_view_proj;
uniform float u_point_px;
in vec3 in_pos;
in vec3 in_color;
in int in_id;
out vec3 v_color;
flat out int v_id;
void main() {
    v_color = in_color;
    v_id = in_id;
    gl_Position = u_view_proj * vec4(in_pos, 1.0);
    gl_PointSize = u_point_px;
}
