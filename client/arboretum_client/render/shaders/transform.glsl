// Vertex inputs every pickable program shares: position, pick id, and the camera's view-projection.
uniform mat4 u_view_proj;
in vec3 in_pos;
in int in_id;

// A world-frame point in clip space.
vec4 clip_from_world(vec3 p_world) {
    return u_view_proj * vec4(p_world, 1.0);
}
