// Highlight (VRTree 3.3): the ids touched by the left and right hand (-1: none) and their colours.
uniform vec2 u_hl_ids;
uniform vec3 u_hl_color0;
uniform vec3 u_hl_color1;

// base, its colour mixed by amount towards each hand touching pick id `id`, alpha raised to min_alpha.
vec4 highlight(int id, vec4 base, float amount, float min_alpha) {
    if (abs(float(id) - u_hl_ids.x) < 0.5) base = vec4(mix(base.rgb, u_hl_color0, amount), max(base.a, min_alpha));
    if (abs(float(id) - u_hl_ids.y) < 0.5) base = vec4(mix(base.rgb, u_hl_color1, amount), max(base.a, min_alpha));
    return base;
}
