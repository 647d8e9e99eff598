#version 330 core
// Final colour and depth of a view: live video where any live projector reached, else retained
// video faded towards the model's colour, else the model's own shaded colour (or the sky).
// Compiled in four variants (the renderer inserts the defines): LIVE when some live projector
// pass drew into this view, RETAINED when some retained one did; the targets of passes that did
// not run are neither cleared nor read.
uniform sampler2D u_gbuffer_color;
uniform sampler2D u_gbuffer_depth;
uniform sampler2D u_live;      // (sum weight * video, sum weight)
uniform sampler2D u_retained;  // same for retained snapshots
uniform sampler2D u_fade;      // r: sum weight * fade of the retained snapshots here
uniform vec3 u_clear_color;
uniform bool u_tint_by_age;

out vec4 o_color;

void main() {
  ivec2 pixel = ivec2(gl_FragCoord.xy);
  vec4 g = texelFetch(u_gbuffer_color, pixel, 0);
  gl_FragDepth = texelFetch(u_gbuffer_depth, pixel, 0).r;
  vec3 color = g.a == 0.0 ? u_clear_color : g.rgb;
#ifdef RETAINED
  vec4 retained = texelFetch(u_retained, pixel, 0);
  if (retained.a > 0.0) {
    float fade = clamp(texelFetch(u_fade, pixel, 0).r / retained.a, 0.0, 1.0);
    vec3 old = retained.rgb / retained.a;
    if (u_tint_by_age) old = 0.5 * old + 0.5 * mix(vec3(0.2, 0.35, 1.0), vec3(1.0, 0.85, 0.1), fade);
    color = mix(color, old, fade);
  }
#endif
#ifdef LIVE
  vec4 live = texelFetch(u_live, pixel, 0);
  if (live.a > 0.0) color = live.rgb / live.a;  // live video wins over retained
#endif
  o_color = vec4(color, 1.0);
}
