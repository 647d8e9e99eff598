#version 330 core
// Depth-only pass from a projector's view into its shadow-map layer.
layout(location = 0) in vec3 a_position;

uniform mat4 u_clip_from_local;

void main() {
  gl_Position = u_clip_from_local * vec4(a_position, 1.0);
}
