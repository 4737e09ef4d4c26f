#version 330 core
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
    f_color = vec4(v_color * (1.0 - 0.25 * r2), 1.0);
#endif
}
