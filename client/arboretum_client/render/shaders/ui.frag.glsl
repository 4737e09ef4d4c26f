#version 330 core
// The UI image (RGBA, top row first, not premultiplied) blended over the frame.
uniform sampler2D u_ui;
in vec2 v_uv;
out vec4 f_color;
void main() {
    f_color = texture(u_ui, v_uv);
}
