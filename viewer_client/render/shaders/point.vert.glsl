#version 330 core
// Point cloud (LiDAR foreground points), local frame; square points of a fixed size in pixels.
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_color;

uniform mat4 u_clip_from_local;
uniform float u_point_size_px;

out vec3 v_color;

void main() {
  v_color = a_color;
  gl_Position = u_clip_from_local * vec4(a_position, 1.0);
  gl_PointSize = u_point_size_px;
}
