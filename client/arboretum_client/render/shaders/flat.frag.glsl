#version 330 core
// Unlit colour (lines, grid).
//#include pick_out.glsl
in vec4 v_color;
flat in int v_id;
void main() {
#ifdef PICK
    f_id = v_id;
#else
    f_color = v_color;
#endif
}
