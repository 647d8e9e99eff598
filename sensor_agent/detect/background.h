#pragma once
// Per-pixel background models of the agent's detector (seed AVE §6): each keeps a model of the
// static scene on a grey image and turns a new frame into a difference image (0..255, larger =
// less like the background) that the histogram threshold (segment.h) cuts.
//
//   kTimeAverage (default)  variable-length time average, a single distribution: the mean and the
//                           mean absolute deviation of the last n frames, n growing from 1 to
//                           window_frames (seed: "variable length time average"); difference =
//                           6 |I - mean| / sigma, sigma = 1.25 MAD floored at 3 grey levels.
//   kGaussian               per-pixel running mean and variance with a fixed learning rate
//                           (2 / window_frames: exponential forgetting); difference = 6 |I - mean| / sigma.
//   kMixture                three Gaussians per pixel (Stauffer-Grimson); difference = 6 |I - mu| /
//                           sigma to the nearest background component.
// Pixels flagged foreground in the previous frame are updated ten times more slowly, so a person
// standing still fades into the background over tens of seconds, not one; except during the first
// window_frames / 5 frames, so objects present at the start leave no lasting ghost.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace ave::detect {

enum class BackgroundKind : uint8_t { kTimeAverage = 0, kGaussian = 1, kMixture = 2 };

// "average", "gaussian", "mixture"; false for anything else.
bool ParseBackgroundKind(const std::string& name, BackgroundKind& kind);
const char* BackgroundKindName(BackgroundKind kind);

class BackgroundModel {
 public:
  virtual ~BackgroundModel() = default;
  // Writes the difference image of `grey` (count pixels) against the model, then learns `grey`
  // except where `previous_foreground` (may be null) is set, which learns slowly. The first
  // frame after construction or Reset() initialises the model and gives an all-zero difference.
  virtual void Apply(const uint8_t* grey, const uint8_t* previous_foreground, uint8_t* difference) = 0;
  // Forget everything: the next frame becomes the background (after a global scene change).
  virtual void Reset() = 0;
  // Mean level of the background's first `count` values, every 7th (for global gain compensation
  // on the grey plane); 0 before the first frame.
  virtual double MeanLevel(size_t count) const = 0;
};

// `pixels` per frame; `window_frames` (>= 1) is the longest averaging window, in frames.
std::unique_ptr<BackgroundModel> MakeBackgroundModel(BackgroundKind kind, size_t pixels, int window_frames);

}  // namespace ave::detect
