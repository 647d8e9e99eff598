#version 330 core
// Final colour and depth of a view: live video where any live projector reached, else retained
// video faded towards the model's colour, else the model's own shaded colour (or the sky).
// Compiled in four variants (the renderer inserts the defines): LIVE when some live projector
// pass drew into this view, RETAINED when some retained one did; the targets of passes that did
// not run are neither cleared nor read. CACHED (a still view, issue 7 performance): the G-buffer
// and retained targets are the view cache's, and live video comes from the cached mapping: up to
// u_entries (video u, v, layer, weight) per pixel, the current frames sampled there and blended by
// weight (the same weights the per-projector passes would sum; more than ENTRIES overlapping
// cameras are truncated to the best ENTRIES). SHADOWED (with CACHED): entries are tested against
// the projectors' shadow maps with the dynamic models in them where the models may hide them (Lit);
// with WITH_DEPTH it is the plain resolve itself, over every pixel (a crowd: ResolveMode::kShadowedAll).
uniform sampler2D u_gbuffer_color;
uniform sampler2D u_gbuffer_depth;
uniform sampler2D u_live;      // (sum weight * video, sum weight)
uniform sampler2D u_retained;  // same for retained snapshots
uniform sampler2D u_fade;      // r: sum weight * fade of the retained snapshots here
uniform vec3 u_clear_color;
uniform bool u_tint_by_age;
// Retained fade since the retained targets were drawn: the weighted mean fade of snapshots scales
// by exactly 0.5^(elapsed / half-life), since every snapshot's fade does (1 when not cached).
uniform float u_fade_scale;
// A view drawn at reduced resolution (RendererOptions::moving_view_scale; never CACHED): its
// targets hold the picture in the lower-left part of the viewport, scaled by u_source_scale.
uniform vec2 u_source_origin;  // the viewport's lower-left corner (framebuffer pixels)
uniform vec2 u_source_scale;
#ifdef CACHED
uniform sampler2DArray u_mapping;  // layers: entries, sorted by weight descending; w = 0: none
uniform sampler2DArray u_video;
uniform bool u_last_wins;          // the first entry that counts (the last projector) alone

vec4 WeightedVideo(vec4 entry) {
  return vec4(entry.w * texture(u_video, entry.xyz).rgb, entry.w);
}
#endif
#ifdef SHADOWED
// Where dynamic models are in some projectors' shadow maps (drawn over the plain cached resolve):
// an entry is tested against its projector's shadow map with the models in it, as the projector
// pass does (the point moved along its normal by about one texel), but only when its video (u, v)
// lies in the rectangle of that projector's image the models may cover (u_model_uv): elsewhere the
// dynamic shadow map equals the static one, whose test the entry passed when the cache was built.
// Drawn over the plain cached resolve only where the stencil says so: the renderer first counts
// there the live projectors' shadow volumes of the models that hold the surface, then, inside
// them, the MARK variant keeps the pixels with an entry the models may hide (llvmpipe runs every
// instruction for every block with a live pixel, both sides of a branch and after a discard, so
// the cost is cut by the stencil test before the shader runs).
uniform sampler2D u_gbuffer_normal;
uniform mat4 u_local_from_window;
uniform sampler2DArrayShadow u_shadow;
uniform mat4 u_shadow_clip_from_local[MAX_PROJECTORS];  // by layer
uniform vec4 u_position_offset[MAX_PROJECTORS];  // projector position (local), normal offset
uniform vec4 u_model_uv[MAX_PROJECTORS];  // (u0, v0, u1, v1) per layer; empty (u0 > u1): no model

bool MayBeHidden(vec4 entry) {
  vec4 r = u_model_uv[int(entry.z + 0.5)];
  return all(greaterThanEqual(entry.xy, r.xy)) && all(lessThanEqual(entry.xy, r.zw));
}

bool Lit(vec4 entry, vec3 position, vec3 n) {
  if (!MayBeHidden(entry)) return true;
  vec4 po = u_position_offset[int(entry.z + 0.5)];
  float distance_m = max(length(po.xyz - position), 1e-6);
  vec4 clip = u_shadow_clip_from_local[int(entry.z + 0.5)] * vec4(position + n * (distance_m * po.w), 1.0);
  vec3 ndc = clip.xyz * (1.0 / max(clip.w, 1e-6));
  return texture(u_shadow, vec4(0.5 * ndc.xy + 0.5, entry.z, 0.5 * ndc.z + 0.5)) > 0.0;
}
#endif

out vec4 o_color;

void main() {
#ifdef MARK
  // Stencil pass before the SHADOWED one: survives only where some entry may be hidden.
  ivec2 pixel = ivec2(gl_FragCoord.xy);
  bool hidden = false;
  for (int k = 0; k < ENTRIES; ++k) {
    vec4 entry = texelFetch(u_mapping, ivec3(pixel, k), 0);
    if (entry.w <= 0.0) break;
    hidden = hidden || MayBeHidden(entry);
  }
  if (!hidden) discard;
  o_color = vec4(0.0);
#else
#ifdef CACHED
  ivec2 pixel = ivec2(gl_FragCoord.xy);
#else
  ivec2 pixel = ivec2(u_source_origin + floor((gl_FragCoord.xy - u_source_origin) * u_source_scale));
#endif
  vec4 g = texelFetch(u_gbuffer_color, pixel, 0);
  float depth = texelFetch(u_gbuffer_depth, pixel, 0).r;
#if !defined(SHADOWED) || defined(WITH_DEPTH)
  gl_FragDepth = depth;  // (SHADOWED: drawn over the plain resolve, depth kept, early stencil test)
#endif
  vec3 color = g.a == 0.0 ? u_clear_color : g.rgb;
#ifdef RETAINED
  vec4 retained = texelFetch(u_retained, pixel, 0);
  if (retained.a > 0.0) {
    float fade = clamp(u_fade_scale * texelFetch(u_fade, pixel, 0).r / retained.a, 0.0, 1.0);
    vec3 old = retained.rgb / retained.a;
    if (u_tint_by_age) old = 0.5 * old + 0.5 * mix(vec3(0.2, 0.35, 1.0), vec3(1.0, 0.85, 0.1), fade);
    color = mix(color, old, fade);
  }
#endif
#ifdef LIVE
#ifdef CACHED
#ifdef SHADOWED
  vec4 local_h = u_local_from_window * vec4(gl_FragCoord.xy, 2.0 * depth - 1.0, 1.0);
  vec3 position = local_h.xyz * (1.0 / local_h.w);
  vec3 n = normalize(2.0 * texelFetch(u_gbuffer_normal, pixel, 0).xyz - 1.0);
#endif
  vec4 live = vec4(0.0);
  for (int k = 0; k < ENTRIES; ++k) {
    vec4 entry = texelFetch(u_mapping, ivec3(pixel, k), 0);
    if (entry.w <= 0.0) break;
#ifdef SHADOWED
    if (!Lit(entry, position, n)) continue;
#endif
    live += WeightedVideo(entry);
    if (u_last_wins) break;
  }
#else
  vec4 live = texelFetch(u_live, pixel, 0);
#endif
  if (live.a > 0.0) color = live.rgb / live.a;  // live video wins over retained
#endif
  o_color = vec4(color, 1.0);
#endif
}
