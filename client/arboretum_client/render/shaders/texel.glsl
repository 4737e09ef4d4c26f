// The base colour of a fragment: the vertex colour, times the texture's RGB for TEXTURED programs,
// whose texels with alpha below u_alpha_cutoff are cut out (discarded: not drawn, not pickable;
// glTF alphaMode MASK).
#ifdef TEXTURED
uniform sampler2D u_texture;
uniform float u_alpha_cutoff;
in vec2 v_uv;
vec4 base_color(vec4 color) {
    vec4 texel = texture(u_texture, v_uv);
    if (texel.a < u_alpha_cutoff) discard;
    return vec4(color.rgb * texel.rgb, color.a);
}
#else
vec4 base_color(vec4 color) { return color; }
#endif
