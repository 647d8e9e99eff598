#pragma once
// A small procedural avatar sequence for tests and benches only (issue 17): a box figure with
// swinging legs, built to avatar_sequence.h's contract, until the studio's reconstructed walks
// exist. Not a studio product and never stored by the shipped tools.
//
// Shape (avatar frame: metres, z up, foot centre at the origin, walking along +x): two legs
// (0.15 x 0.15 x 0.85 m) swinging about the hip by +-swing, a torso (0.25 x 0.45 x 0.6 m), a head
// (0.22 m cube) at 1.5..1.72 m and a nose (0.10 m cube) on the +x face of the head, so the facing
// direction is visible from above. Each part samples its own colour cell of the atlas.
#include <array>
#include <cstdint>

#include "model_store/avatar/avatar_sequence.h"

namespace ave::avatar {

struct ProceduralAvatarOptions {
  int frame_count = 12;
  double cycle_s = 1.1;        // one full walk cycle (two steps)
  double stride_m = 1.4;       // metres walked per cycle
  double swing_rad = 0.45;     // leg swing amplitude
  int atlas_side = 32;         // pixels, square atlas of 4 x 4 colour cells
};

// The colours of the parts in the atlas (RGB8): legs, torso, head, nose.
inline constexpr std::array<std::array<uint8_t, 3>, 4> kProceduralPartRgb = {{
    {{40, 60, 200}}, {{200, 40, 40}}, {{230, 190, 150}}, {{40, 220, 40}}}};

AvatarSequence MakeProceduralWalk(const ProceduralAvatarOptions& options = {}, const char* name = "procedural-walk");

}  // namespace ave::avatar
