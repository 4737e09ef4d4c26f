#version 330 core
// Meshes and tubes: per-vertex position, normal, colour and pick id (world frame); with TEXTURED
// also texture coordinates.
//#include transform.glsl
in vec3 in_normal;
in vec4 in_color;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_color;
flat out int v_id;
//#include uv_pass.glsl
void main() {
    v_pos = in_pos;
    v_normal = in_normal;
    v_color = in_color;
    v_id = in_id;
    pass_uv();
    gl_Position = clip_from_world(in_pos);
}
