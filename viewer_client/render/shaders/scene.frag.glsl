#version 330 core
// Projective texture mapping with shadow-map visibility (AVE paper sections 7-8).
//
// Every projector is a camera: its video frame lies in layer u_projector_layer[i] of u_video (top
// row at t = 0) and its depth from the projector's own view in the same layer of u_shadow. A
// fragment takes a projector's video where it lies inside that projector's frustum, faces it and
// passes its shadow test; overlapping projectors blend with weight cos^2 of the view angle. The
// video is shown unlit, so a projected pixel equals the camera's pixel. Elsewhere the model keeps
// its own shaded colour.
//
// MAX_PROJECTORS must equal ave::viewer::kMaxProjectors (uniform arrays; issue 7 raises it).
// The lookups sit in `if (inside)`: llvmpipe skips them for blocks wholly outside a frustum. Both
// are safe in non-uniform control flow: the video uses textureLod and the shadow map has no mipmaps
// and one filter (textureLod on shadow arrays does not compile under llvmpipe).
#define MAX_PROJECTORS 16

in vec3 v_position;
in vec3 v_normal;
in vec3 v_color;

uniform vec3 u_sun_direction;  // unit, towards the sun
uniform float u_ambient;
uniform float u_diffuse;

uniform int u_projector_count;
uniform mat4 u_projector_clip_from_local[MAX_PROJECTORS];
uniform vec3 u_projector_position[MAX_PROJECTORS];  // local frame
uniform float u_projector_layer[MAX_PROJECTORS];
// Shadow lookups move the point off the surface along its normal by this many metres per metre of
// distance to the projector (about one shadow-map texel), which removes acne on grazing surfaces
// without the peter-panning a large constant depth bias gives at building feet.
uniform float u_projector_normal_offset[MAX_PROJECTORS];

uniform sampler2DArray u_video;
uniform sampler2DArrayShadow u_shadow;

out vec4 o_color;

void main() {
  vec3 n = normalize(v_normal);
  vec3 shaded = v_color * (u_ambient + u_diffuse * max(dot(n, u_sun_direction), 0.0));

  vec3 video_sum = vec3(0.0);
  float weight_sum = 0.0;
  float coverage = 0.0;
  for (int i = 0; i < u_projector_count; ++i) {
    vec3 to_projector = u_projector_position[i] - v_position;
    float distance_m = max(length(to_projector), 1e-6);
    float facing = dot(n, to_projector) / distance_m;

    vec4 clip = u_projector_clip_from_local[i] * vec4(v_position, 1.0);
    vec3 ndc = clip.xyz / max(clip.w, 1e-6);
    bool inside = clip.w > 0.0 && all(lessThanEqual(abs(ndc), vec3(1.0))) && facing > 0.0;

    if (inside) {
      vec3 p_shadow = v_position + n * (distance_m * u_projector_normal_offset[i]);
      vec4 clip_shadow = u_projector_clip_from_local[i] * vec4(p_shadow, 1.0);
      vec3 ndc_shadow = clip_shadow.xyz / max(clip_shadow.w, 1e-6);
      float lit = texture(u_shadow, vec4(0.5 * ndc_shadow.xy + 0.5, u_projector_layer[i], 0.5 * ndc_shadow.z + 0.5));
      vec3 video = textureLod(u_video, vec3(0.5 + 0.5 * ndc.x, 0.5 - 0.5 * ndc.y, u_projector_layer[i]), 0.0).rgb;
      float weight = lit * facing * facing;
      video_sum += weight * video;
      weight_sum += weight;
      coverage = max(coverage, lit);
    }
  }
  vec3 video = weight_sum > 0.0 ? video_sum / weight_sum : shaded;
  o_color = vec4(mix(shaded, video, coverage), 1.0);
}
