#version 330 core
// G-buffer: the model's own shaded colour (alpha = surface kind: 1 model, 0.5 sky dome, 0 nothing)
// and the unit normal packed into [0, 1]. Depth comes from the depth attachment. Sky dome vertices
// carry colour r < 0 and take the view's sky colour instead.
in vec3 v_normal;
in vec3 v_color;

uniform vec3 u_sun_direction;  // unit, towards the sun
uniform float u_ambient;
uniform float u_diffuse;
uniform vec3 u_sky_color;

layout(location = 0) out vec4 o_color;
layout(location = 1) out vec4 o_normal;

void main() {
  vec3 n = normalize(v_normal);
  o_normal = vec4(0.5 * n + 0.5, 1.0);
  if (v_color.r < 0.0) {
    o_color = vec4(u_sky_color, 0.5);
    return;
  }
  o_color = vec4(v_color * (u_ambient + u_diffuse * max(dot(n, u_sun_direction), 0.0)), 1.0);
}
