#version 330 core
// One mesh drawn N times: per-instance model matrix ('16f/i'), colour and pick id; with TEXTURED
// also per-vertex texture coordinates.
//#include transform.glsl
in vec3 in_normal;
in mat4 in_model;
in vec3 in_icolor;
out vec3 v_pos;
out vec3 v_normal;
out vec4 v_color;
flat out int v_id;
//#include uv_pass.glsl
void main() {
    vec4 world = in_model * vec4(in_pos, 1.0);
    v_pos = world.xyz;
    v_normal = mat3(in_model) * in_normal;
    v_color = vec4(in_icolor, 1.0);
    v_id = in_id;
    pass_uv();
    gl_Position = u_view_proj * world;
}
