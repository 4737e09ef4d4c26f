#version 330 core
// Round dots shaded darker towards their rim.
//#include pick_out.glsl
//#include highlight.glsl
in vec3 v_color;
flat in int v_id;
void main() {
    vec2 d = gl_PointCoord * 2.0 - 1.0;
    float r2 = dot(d, d);
    if (r2 > 1.0) discard;
#ifdef PICK
    f_id = v_id;
#else
    vec3 c = highlight(v_id, vec4(v_color, 1.0), 0.6, 1.0).rgb;
    f_color = vec4(c * (1.0 - 0.25 * r2), 1.0);
#endif
}
