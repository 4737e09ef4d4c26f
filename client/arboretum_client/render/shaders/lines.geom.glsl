#version 330 core
// Expands each segment into a quad u_width_px wide in the viewport (both ends in front of the eye).
layout(lines) in;
layout(triangle_strip, max_vertices = 4) out;
uniform vec2 u_viewport;  // half the viewport size in pixels
uniform float u_width_px;
in vec4 g_color[];
flat in int g_id[];
out vec4 v_color;
flat out int v_id;
void main() {
    vec4 p0 = gl_in[0].gl_Position;
    vec4 p1 = gl_in[1].gl_Position;
    if (p0.w <= 0.0 || p1.w <= 0.0) return;
    vec2 s0 = p0.xy / p0.w * u_viewport;
    vec2 s1 = p1.xy / p1.w * u_viewport;
    vec2 d = s1 - s0;
    d = length(d) > 1e-6 ? normalize(d) : vec2(1.0, 0.0);
    vec2 off = vec2(-d.y, d.x) * 0.5 * u_width_px / u_viewport;
    v_color = g_color[0]; v_id = g_id[0];
    gl_Position = p0 + vec4(off * p0.w, 0.0, 0.0); EmitVertex();
    gl_Position = p0 - vec4(off * p0.w, 0.0, 0.0); EmitVertex();
    v_color = g_color[1]; v_id = g_id[1];
    gl_Position = p1 + vec4(off * p1.w, 0.0, 0.0); EmitVertex();
    gl_Position = p1 - vec4(off * p1.w, 0.0, 0.0); EmitVertex();
    EndPrimitive();
}
