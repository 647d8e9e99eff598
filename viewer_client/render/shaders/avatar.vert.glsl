#version 330 core
// Avatars (issue 17): one instanced draw per (sequence, frame); each instance is a person, its
// model matrix (avatar frame -> local frame: heading about z, foot centre at the ground contact)
// in attributes 3..6. The same program draws the G-buffer and the projectors' shadow maps.
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec2 a_uv;
layout(location = 3) in vec4 a_model_col0;
layout(location = 4) in vec4 a_model_col1;
layout(location = 5) in vec4 a_model_col2;
layout(location = 6) in vec4 a_model_col3;

uniform mat4 u_clip_from_local;

out vec3 v_normal;
out vec2 v_uv;

void main() {
  mat4 local_from_avatar = mat4(a_model_col0, a_model_col1, a_model_col2, a_model_col3);
  v_normal = mat3(local_from_avatar) * a_normal;  // rotation about z only: no inverse transpose
  v_uv = a_uv;
  gl_Position = u_clip_from_local * (local_from_avatar * vec4(a_position, 1.0));
}
