#version 330 core
// Headlight (diffuse + a little specular) over a hemisphere ambient; two-sided.
uniform vec3 u_eye;
uniform vec3 u_sky;
uniform vec3 u_ground;
// Highlight (VRTree 3.3): the ids touched by the left and right hand (-1: none) and their colours.
uniform vec2 u_hl_ids;
uniform vec3 u_hl_color0;
uniform vec3 u_hl_color1;
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
flat in int v_id;
#ifdef PICK
out int f_id;
#else
out vec4 f_color;
#endif
void main() {
#ifdef PICK
    f_id = v_id;
#else
    vec3 n = normalize(v_normal);
    vec3 v = normalize(u_eye - v_pos);
    if (dot(n, v) < 0.0) n = -n;
    vec3 ambient = mix(u_ground, u_sky, 0.5 + 0.5 * n.z);
    float diffuse = max(dot(n, v), 0.0);
    float specular = 0.12 * pow(diffuse, 40.0);
    vec4 base = v_color;
    if (abs(float(v_id) - u_hl_ids.x) < 0.5) base = vec4(mix(base.rgb, u_hl_color0, 0.7), max(base.a, 0.55));
    if (abs(float(v_id) - u_hl_ids.y) < 0.5) base = vec4(mix(base.rgb, u_hl_color1, 0.7), max(base.a, 0.55));
    vec3 rgb = base.rgb * (0.45 * ambient + 0.62 * diffuse) + specular;
    f_color = vec4(min(rgb, vec3(1.0)), base.a);
#endif
}
