#version 330 core
// One projector's footprint: the back faces of its frustum volume, drawn in the view (the view's
// matrix, not the projector's: drawn with the projector's own matrix the volume would cover the
// whole viewport in every pass).
layout(location = 0) in vec3 a_position;

uniform mat4 u_view_clip_from_local;

void main() {
  gl_Position = u_view_clip_from_local * vec4(a_position, 1.0);
}
