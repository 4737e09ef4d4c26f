#version 330 core
// Headlight (diffuse + a little specular) over a hemisphere ambient; two-sided.
//#include pick_out.glsl
//#include highlight.glsl
//#include texel.glsl
uniform vec3 u_eye;
uniform vec3 u_sky;
uniform vec3 u_ground;
in vec3 v_pos;
in vec3 v_normal;
in vec4 v_color;
flat in int v_id;
void main() {
    vec4 color = base_color(v_color);
#ifdef PICK
    f_id = v_id;
#else
    vec3 n = normalize(v_normal);
    vec3 v = normalize(u_eye - v_pos);
    if (dot(n, v) < 0.0) n = -n;
    vec3 ambient = mix(u_ground, u_sky, 0.5 + 0.5 * n.z);
    float diffuse = max(dot(n, v), 0.0);
    float specular = 0.12 * pow(diffuse, 40.0);
    vec4 base = highlight(v_id, color, 0.7, 0.55);
    vec3 rgb = base.rgb * (0.45 * ambient + 0.62 * diffuse) + specular;
    f_color = vec4(min(rgb, vec3(1.0)), base.a);
#endif
}
