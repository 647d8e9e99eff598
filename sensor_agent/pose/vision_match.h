#pragma once
// Internal to the vision front end (vision.cc, vision_keyframe.cc, vision_match.cc and their tests): image-side
// matching helpers. Includes OpenCV; do not include from public headers.
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "model_store/geometry/camera.h"

namespace ave::pose::internal {

inline constexpr double kBorder_px = 8;       // predictions closer than this to the image edge are skipped
inline constexpr double kChamferCap_px = 8;   // coarse pass: edge distances are truncated here
inline constexpr double kEdgeSample_px = 4;   // coarse pass: spacing of samples along a predicted model edge
inline constexpr double kCoarseMatch_px = 6;  // coarse pass: match radius once the offset is applied
inline constexpr double kMinSegment_px = 20;  // line segments shorter than this are ignored
inline constexpr double kMaxAngle_rad = 0.035;  // ~2°: a segment's direction against the predicted line's

struct Segment {
  Eigen::Vector2d a, b;
};

inline bool InImage(const PinholeIntrinsics& k, const Eigen::Vector2d& uv, double border) {
  return uv.x() >= border && uv.y() >= border && uv.x() <= k.width - 1 - border && uv.y() <= k.height - 1 - border;
}

// Nearest detected corner to `uv` within `radius`; -1 when none.
int Nearest(const std::vector<cv::Point2f>& corners, const Eigen::Vector2d& uv, double radius);

// The image offset (within `radius`) that best lays the sampled model-edge pixels on the frame's
// edges (chamfer: mean distance, truncated, from the distance transform) plus the skyline samples
// on the frame's skyline; a `coarse_step` px grid over the window, then halved steps around the best
// down to 1 px.
Eigen::Vector2d ChamferOffset(const cv::Mat& edge_distance, const std::vector<Eigen::Vector2d>& samples, const cv::Mat& skyline_distance,
                              const std::vector<Eigen::Vector2d>& sky_samples, double radius, int coarse_step = 2);

// The image motion that best lays the model edges on the frame's: an offset (px) and a rotation
// about `centre` (the principal point; rad, positive turns +u towards +v). A camera rolled by r
// shows its image turned by -r about the principal point.
struct ImageAlignment {
  Eigen::Vector2d offset = Eigen::Vector2d::Zero();
  double rotation_rad = 0;
  // The chamfer score at the best motion (mean truncated edge distance, sky term added); +infinity
  // when fewer than 10 edge samples are in view (nothing to score).
  double score_px = 0;
  Eigen::Vector2d Apply(const Eigen::Vector2d& uv, const Eigen::Vector2d& centre) const {
    const double c = std::cos(rotation_rad), s = std::sin(rotation_rad);
    const Eigen::Vector2d d = uv - centre;
    return centre + Eigen::Vector2d(c * d.x() - s * d.y(), s * d.x() + c * d.y()) + offset;
  }
};

// ChamferOffset, and then, when max_rotation_rad > 0, image rotations about `centre` in steps of
// rotation_step_rad up to +-max_rotation_rad, each with the offset searched again within 8 px of
// the unrotated best (issue 19: an AHRS roll error of 1.5 deg moves the image's edges 8 px, beyond
// the coarse match radius, so a translation alone leaves roll to the few central corners).
ImageAlignment ChamferAlign(const cv::Mat& edge_distance, const std::vector<Eigen::Vector2d>& samples, const cv::Mat& skyline_distance,
                            const std::vector<Eigen::Vector2d>& sky_samples, double radius, const Eigen::Vector2d& centre,
                            double max_rotation_rad, double rotation_step_rad, int coarse_step = 2);

// Distance transforms of the Canny edges and of the skyline (in each column, the first edge pixel
// from the top) of a grey frame.
void EdgeDistances(const cv::Mat& gray, cv::Mat& edge_distance, cv::Mat& skyline_distance);

// Unique matches (prediction index into `predicted`'s owners, corner index) of predicted pixels
// within `radius` of prediction + offset; a corner claimed by two predictions is dropped.
std::vector<std::pair<int, int>> MatchPoints(const std::vector<std::pair<int, Eigen::Vector2d>>& predicted,
                                             const std::vector<cv::Point2f>& corners, const Eigen::Vector2d& offset, double radius);

// Edge points near a predicted image curve (frame pixels, `samples` of them given): for each, the
// strongest intensity step within `reach_px` along `normal` (unit), to sub-pixel by a parabola
// through the step and its neighbours; steps weaker than `min_step` (grey levels per pixel) are
// skipped. Model-based edge tracking in the manner of RAPiD / moving edges.
std::vector<cv::Point2f> SearchEdge(const cv::Mat& gray, const std::vector<Eigen::Vector2d>& samples, const Eigen::Vector2d& normal,
                                    double reach_px, double min_step);

// A model corner located where its edges meet in the frame (issue 19, thirteenth session), instead
// of where a gradient corner detector puts it (inside the wedge of a blurred corner, up to 1.5 px at
// a gable's apex). `directions` are the corner's model edges as the pose projects them (unit, frame
// pixels, pointing away from the corner). Along each, edge points are searched across the edge
// (SearchEdge, within reach_px) at 3..(3 + samples) px from `seed`; the edge counts when at least
// two thirds of its samples step, a line fits them within 0.5 px RMS and it runs within 10 deg of
// the prediction. The two counted edges farthest from parallel (at least 20 deg apart) are
// intersected. nullopt when fewer than two edges count or the meeting point is more than
// `max_move_px` from the seed.
std::optional<Eigen::Vector2d> CornerOnEdges(const cv::Mat& gray, const Eigen::Vector2d& seed, const std::vector<Eigen::Vector2d>& directions,
                                             int samples, double reach_px, double min_step, double max_move_px);

// A coarse occupancy grid over the image (cells of `cell_px`), to detect new corners only where
// the tracked set is thin.
class CellGrid {
 public:
  CellGrid(int width, int height, int cell_px);
  void Add(double u, double v);
  int Count(double u, double v) const;
  // 255 in cells with fewer than `below` entries, 0 elsewhere, at 1/`scale` of the image size.
  cv::Mat ThinMask(int below, int scale) const;

 private:
  int width_, height_, cell_, cols_, rows_;
  std::vector<int> count_;
};

}  // namespace ave::pose::internal
