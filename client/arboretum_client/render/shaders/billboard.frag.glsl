#version 330 core
// The billboard's image (RGBA, not premultiplied), alpha-blended; fully transparent texels are
// discarded so they write no depth.
//#include pick_out.glsl
uniform sampler2D u_image;
in vec2 v_uv;
void main() {
    vec4 texel = texture(u_image, v_uv);
    if (texel.a < 0.004) discard;
#ifdef PICK
    f_id = 0;
#else
    f_color = texel;
#endif
}
