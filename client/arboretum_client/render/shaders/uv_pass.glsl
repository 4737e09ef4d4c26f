// Texture coordinates handed from the vertex to the fragment stage (TEXTURED programs only).
#ifdef TEXTURED
in vec2 in_uv;
out vec2 v_uv;
void pass_uv() { v_uv = in_uv; }
#else
void pass_uv() {}
#endif
