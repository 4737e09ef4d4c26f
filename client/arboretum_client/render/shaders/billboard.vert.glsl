#version 330 core
// A textured rectangle in the world (reference images): four corners of a triangle strip made from
// gl_VertexID, centre plus or minus its right and up half-extent vectors; no vertex buffer.
//#include transform.glsl
uniform vec3 u_center;
uniform vec3 u_right;
uniform vec3 u_up;
out vec2 v_uv;
void main() {
    vec2 c = vec2(float((gl_VertexID & 1) * 2 - 1), float((gl_VertexID & 2) - 1));
    v_uv = vec2(0.5 + 0.5 * c.x, 0.5 - 0.5 * c.y);  // image rows are stored top row first
    gl_Position = clip_from_world(u_center + c.x * u_right + c.y * u_up);
}
