#version 330 core
uniform vec2 u_hl_ids;
uniform vec3 u_hl_color0;
uniform vec3 u_hl_color1;
in vec3 v_color;
flat in int v_id;
#ifdef PICK
out int f_id;
#else
out vec4 f_color;
#endif
void main() {
    vec2 d = gl_PointCoord * 2.0 - 1.0;
    float r2 = dot(d, d);
    if (r2 > 1.0) discard;
#ifdef PICK
    f_id = v_id;
#else
    vec3 c = v_color;
    if (abs(float(v_id) - u_hl_ids.x) < 0.5) c = mix(c, u_hl_color0, 0.6);
    if (abs(float(v_id) - u_hl_ids.y) < 0.5) c = mix(c, u_hl_color1, 0.6);
    f_color = vec4(c * (1.0 - 0.25 * r2), 1.0);
#endif
}
