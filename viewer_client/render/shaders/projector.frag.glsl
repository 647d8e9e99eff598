#version 330 core
// Projective texture mapping with shadow-map visibility (AVE paper sections 7-8), one projector per
// pass, deferred: the surface point comes from the G-buffer under this pixel.
//
// The video frame lies in layer u_layer of u_video (top row at t = 0), the projector's depth in the
// same layer of u_shadow, rendered with u_shadow_clip_from_local (the projection widened by the
// distortion margin). A point takes the video where it lies inside the frustum (near..far and the
// distorted image), faces the projector and passes the shadow test. Output 0: (weight * video,
// weight), summed by blending (last-wins: replaced); output 1: weight * fade of a retained
// snapshot, summed (so the resolve gets the weighted mean fade). With MAPPING defined it records
// where the video comes from instead (see InsertEntry).
//
// Cost (llvmpipe runs every instruction for every pixel of the footprint unless a whole block of
// pixels has discarded): the cheapest rejections come first. The window position and depth give
// the surface point and its clip coordinate in the projector, so pixels outside the frustum or the
// image die before the normal is fetched; the shadow-map coordinate reuses the clip coordinate
// (the shadow projection only widens x and y) plus the normal offset; divisions are reciprocals,
// no pow(). (Folding the view's inverse and the projector's matrix into one matrix saves one more
// product but loses enough float precision on far points to double the visibility error against
// 4096 px shadow maps: the point is computed first.)
#ifdef EARLY_TESTS
// The models' pixels of a cached view only (issue 17): the stencil test runs before the shader in
// spite of its discards, so llvmpipe skips every block without a model pixel.
layout(early_fragment_tests) in;
#endif
uniform sampler2D u_gbuffer_normal;  // packed unit normal; a: 0 where nothing was drawn
uniform sampler2D u_gbuffer_depth;   // window depth in [0, 1]
uniform mat4 u_local_from_window;   // local point (homogeneous) from (window x, y, NDC z, 1) of the view

uniform mat4 u_clip_from_local;        // this projector's projection * view
uniform mat4 u_shadow_clip_from_local;  // the widened projection used for its shadow map
uniform float u_shadow_widen;           // 1 / distortion margin: shadow clip xy = clip xy * this
uniform vec3 u_projector_position;      // local frame
uniform vec4 u_pinhole;                 // P00, P02, P11, P12 of the projection
uniform vec4 u_k1_k2_p1_p2;
uniform float u_k3;
uniform bool u_distorted;
uniform float u_layer;
// Shadow lookups move the point off the surface along its normal by this many metres per metre of
// distance to the projector (about one shadow-map texel): no acne on grazing surfaces, and none of
// the peter-panning a large constant depth bias gives at building feet.
uniform float u_normal_offset;
uniform float u_feather;      // NDC distance from the image border over which the weight ramps up
uniform bool u_best_view;     // weight to the 4th power (best view), else as is (blend)
uniform bool u_last_wins;
uniform float u_fade;         // 1 for live projectors; 0.5^(age / half-life) for retained ones
uniform float u_weight_scale; // retained: fade^16 so newer snapshots win

uniform sampler2DArray u_video;
uniform sampler2DArrayShadow u_shadow;

#ifdef COMBINED
// Live projectors drawn in one full-screen pass (the renderer defines COMBINED and BATCH): the
// point is reconstructed and its normal fetched once, then each of the u_count projectors below
// is tested as the per-projector pass would, summed in the shader (last-wins: the last one that
// reaches the pixel). Batches are added by blending (last-wins: a batch that reaches no
// projector here discards, so earlier batches stay).
uniform int u_count;
uniform mat4 u_clips[BATCH];
uniform mat4 u_shadow_clips[BATCH];
uniform vec4 u_pinholes[BATCH];
uniform vec4 u_distortions[BATCH];     // k1 k2 p1 p2
uniform vec4 u_position_layers[BATCH];  // projector position (local), layer
uniform vec4 u_extras[BATCH];           // shadow widen, k3, distorted (0 / 1), normal offset
#endif

layout(location = 0) out vec4 o_accum;
layout(location = 1) out vec4 o_fade;

#ifdef MAPPING
// View cache build (issue 7 performance; the renderer defines MAPPING and ENTRIES and enables
// ARB_shader_image_load_store): instead of blending colour, the pass inserts (video u, v, layer,
// rank) into this pixel's ENTRIES best entries, layers 0.. of u_mapping sorted by rank descending
// (rank 0: empty). Each projector's volume covers a pixel once per draw and the renderer puts a
// memory barrier between draws, so the read-modify-write below needs no atomics.
layout(rgba32f) coherent uniform image2DArray u_mapping;

void InsertEntry(ivec2 pixel, vec4 entry) {
  for (int k = 0; k < ENTRIES; ++k) {
    vec4 current = imageLoad(u_mapping, ivec3(pixel, k));
    if (entry.w > current.w) {
      imageStore(u_mapping, ivec3(pixel, k), entry);
      entry = current;
      if (entry.w <= 0.0) return;
    }
  }
}
#endif

// Where a surface point falls in a projector's image: false outside its frustum or image; ndc
// (distortion applied) and `inside` (distance to the nearest image border, NDC) otherwise.
bool ImagePoint(vec4 clip, vec4 pinhole, vec4 k1_k2_p1_p2, float k3, bool distorted, out vec2 ndc, out float inside) {
  ndc = vec2(0.0);
  inside = -1.0;
  if (clip.w <= 0.0 || abs(clip.z) > clip.w) return false;
  ndc = clip.xy * (1.0 / clip.w);
  if (distorted) {
    // Forward Brown-Conrady model on the normalised (OpenCV) coordinates of the undistorted ray.
    vec2 x = vec2((ndc.x + pinhole.y) / pinhole.x, -(ndc.y + pinhole.w) / pinhole.z);
    float r2 = dot(x, x);
    float radial = 1.0 + r2 * (k1_k2_p1_p2.x + r2 * (k1_k2_p1_p2.y + r2 * k3));
    float p1 = k1_k2_p1_p2.z, p2 = k1_k2_p1_p2.w;
    vec2 xd = x * radial + vec2(2.0 * p1 * x.x * x.y + p2 * (r2 + 2.0 * x.x * x.x),
                                p1 * (r2 + 2.0 * x.y * x.y) + 2.0 * p2 * x.x * x.y);
    ndc = vec2(pinhole.x * xd.x - pinhole.y, -pinhole.z * xd.y - pinhole.w);
  }
  vec2 border = 1.0 - abs(ndc);
  inside = min(border.x, border.y);
  return inside >= 0.0;
}

// The projector's weight at a surface point (position, unit normal n) inside its image (clip, ndc,
// inside from ImagePoint); 0 where the point faces away or is in shadow. u_weight_scale applies.
float ProjectorWeight(vec3 position, vec3 n, vec4 clip, vec2 ndc, float inside, vec3 projector_position,
                      mat4 shadow_clip_from_local, float shadow_widen, float normal_offset, float layer, float focal) {
  vec3 to_projector = projector_position - position;
  float distance_m = max(length(to_projector), 1e-6);
  float inv_distance = 1.0 / distance_m;
  float facing = dot(n, to_projector) * inv_distance;
  // Within 0.57 degrees of edge-on counts as facing away. The G-buffer's 8-bit normal cannot hold
  // an exact 0 (0.5 * 255 is rounded to 127 or 128 by driver: +-0.004), so a wall in the
  // projector's own plane read facing = +-0.004, lit on NVIDIA's driver and not on llvmpipe; and a
  // surface that close to edge-on would smear each video pixel over a hundred of its own.
  if (facing <= 0.01) return 0.0;

  // The shadow clip coordinate of position + n * distance_m * normal_offset.
  vec4 clip_shadow = vec4(clip.xy * shadow_widen, clip.zw) +
                     (distance_m * normal_offset) * (shadow_clip_from_local * vec4(n, 0.0));
  vec3 ndc_shadow = clip_shadow.xyz * (1.0 / max(clip_shadow.w, 1e-6));
  if (any(greaterThan(abs(ndc_shadow.xy), vec2(1.0)))) return 0.0;
  float lit = texture(u_shadow, vec4(0.5 * ndc_shadow.xy + 0.5, layer, 0.5 * ndc_shadow.z + 0.5));
  if (lit <= 0.0) return 0.0;
  if (u_last_wins) return 1.0;
  // Resolution: metres of surface per image pixel grow as distance / (focal * facing).
  float resolution = focal / max(distance_m, 0.5);
  float feather = u_feather > 0.0 ? smoothstep(0.0, u_feather, inside) : 1.0;
  float w = max(facing * resolution * resolution * 100.0, 1e-8);
  if (u_best_view) w = (w * w) * (w * w);
  return w * max(feather, 1e-3) * u_weight_scale;
}

vec2 VideoUv(vec2 ndc) { return vec2(0.5 + 0.5 * ndc.x, 0.5 - 0.5 * ndc.y); }

void main() {
  ivec2 pixel = ivec2(gl_FragCoord.xy);
  float depth = texelFetch(u_gbuffer_depth, pixel, 0).r;
  if (depth == 1.0) discard;  // cleared: nothing drawn here
  // x, y in window pixels, z in NDC: 2 depth - 1 is exact in float, where folding it into the
  // matrix would cost ~5x the precision of far points (visible against 4096 px shadow maps).
  vec4 window = vec4(gl_FragCoord.xy, 2.0 * depth - 1.0, 1.0);
  vec4 local_h = u_local_from_window * window;
  float inv_w = 1.0 / local_h.w;
  vec3 position = local_h.xyz * inv_w;
#ifdef COMBINED
  vec4 packed_normal = texelFetch(u_gbuffer_normal, pixel, 0);
  if (packed_normal.a < 0.75) discard;  // nothing drawn (0), or no video here (0.5: avatar_pass)
  vec3 n = normalize(2.0 * packed_normal.xyz - 1.0);
  vec4 sum = vec4(0.0);
  for (int k = 0; k < u_count; ++k) {
    vec4 clip = u_clips[k] * vec4(position, 1.0);
    vec2 ndc;
    float inside;
    vec4 extra = u_extras[k];  // shadow widen, k3, distorted, normal offset
    if (!ImagePoint(clip, u_pinholes[k], u_distortions[k], extra.y, extra.z > 0.5, ndc, inside)) continue;
    vec4 position_layer = u_position_layers[k];
    float weight = ProjectorWeight(position, n, clip, ndc, inside, position_layer.xyz, u_shadow_clips[k], extra.x,
                                   extra.w, position_layer.w, u_pinholes[k].x);
    if (weight <= 0.0) continue;
    vec3 video = texture(u_video, vec3(VideoUv(ndc), position_layer.w)).rgb;
    sum = u_last_wins ? vec4(video, 1.0) : sum + vec4(weight * video, weight);
  }
  if (sum.a <= 0.0) discard;
  o_accum = sum;
  o_fade = vec4(0.0, 0.0, 0.0, 1.0);
#else
  vec4 clip = u_clip_from_local * vec4(position, 1.0);
  vec2 ndc;
  float inside;
  if (!ImagePoint(clip, u_pinhole, u_k1_k2_p1_p2, u_k3, u_distorted, ndc, inside)) discard;

  vec4 packed_normal = texelFetch(u_gbuffer_normal, pixel, 0);
  if (packed_normal.a < 0.75) discard;  // nothing drawn (0), or no video here (0.5: avatar_pass)
  vec3 n = normalize(2.0 * packed_normal.xyz - 1.0);
  float weight = ProjectorWeight(position, n, clip, ndc, inside, u_projector_position, u_shadow_clip_from_local,
                                 u_shadow_widen, u_normal_offset, u_layer, u_pinhole.x);
  if (weight <= 0.0) discard;
  vec2 uv = VideoUv(ndc);
#ifdef MAPPING
  // Last-wins ranks by list order (layer + 1), the others by weight; the cached resolve reads the
  // first entry only for last-wins.
  InsertEntry(pixel, vec4(uv, u_layer, u_last_wins ? u_layer + 1.0 : weight));
#else
  vec3 video = texture(u_video, vec3(uv, u_layer)).rgb;
  o_accum = u_last_wins ? vec4(video, 1.0) : vec4(weight * video, weight);
  o_fade = vec4(weight * u_fade, 0.0, 0.0, 1.0);
#endif
#endif
}
