#version 330 core
// Avatars into the G-buffer: the frame's atlas colour, shaded like the other models (alpha 1:
// a model). The normal's alpha says whether projected video may land here: 1 yes, 0.5 no (the
// privacy export: people show their own texture only; projector.frag skips normal alpha < 0.75).
in vec3 v_normal;
in vec2 v_uv;

uniform sampler2DArray u_atlas;
uniform float u_layer;  // the frame's atlas layer
uniform vec3 u_sun_direction;
uniform float u_ambient;
uniform float u_diffuse;
uniform float u_receive_video;  // 1 or 0

layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_normal;

void main() {
  vec3 n = normalize(v_normal);
  o_normal = vec4(0.5 * n + 0.5, u_receive_video > 0.5 ? 1.0 : 0.5);
  vec3 albedo = texture(u_atlas, vec3(v_uv, u_layer)).rgb;
  o_color = vec4(albedo * (u_ambient + u_diffuse * max(dot(n, u_sun_direction), 0.0)), 1.0);
}
