#version 330 core
// Unlit colour (lines, grid).
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
    f_color = v_color;
#endif
}
