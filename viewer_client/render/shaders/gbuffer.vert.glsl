#version 330 core
// Static geometry, dynamic models and the sky dome into the G-buffer; local frame (metres, float
// relative to the mesh origin).
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec3 a_color;

uniform mat4 u_clip_from_local;

out vec3 v_normal;
out vec3 v_color;

void main() {
  v_normal = a_normal;
  v_color = a_color;
  gl_Position = u_clip_from_local * vec4(a_position, 1.0);
}
