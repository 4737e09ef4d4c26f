#version 330 core
// Round screen-space dots of a fixed size in pixels.
//#include transform.glsl
uniform float u_point_px;
in vec3 in_color;
out vec3 v_color;
flat out int v_id;
void main() {
    v_color = in_color;
    v_id = in_id;
    gl_Position = clip_from_world(in_pos);
    gl_PointSize = u_point_px;
}
