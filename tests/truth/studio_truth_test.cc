// model_store/studio on the simulated studio, scored against the simulator's truth, and the hard
// cases of issue 17 on real renders: a camera whose silhouette is empty or all foreground, the
// actor partly outside one camera's view, an image of the wrong size. 20 mm voxels keep it fast;
// the accuracy per voxel size is ave-bench studio's.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "model_store/studio/photo_carve.h"
#include "model_store/studio/reconstruct.h"
#include "sensor_agent/sim/studio.h"
#include "tests/truth/studio_truth.h"

namespace ave::studio::testing {
namespace {

ReconstructOptions Options20mm() {
  ReconstructOptions o;
  o.hull.voxel_m = 0.02;
  return o;
}

class StudioTruth : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    absl::StatusOr<SimulatedFrameSet> s = SimulateStudioFrameSet(3);
    ASSERT_TRUE(s.ok()) << s.status();
    set_ = new SimulatedFrameSet(*std::move(s));
    absl::StatusOr<FrameSetResult> r = ReconstructFrameSet(set_->cameras, set_->images, set_->backgrounds, Options20mm());
    ASSERT_TRUE(r.ok()) << r.status();
    good_iou_ = HullVolumeIoU(r->hull, set_->truth_mesh);
  }
  static void TearDownTestSuite() { delete set_; }
  static double IoU(const std::vector<StudioCameraModel>& cameras, const std::vector<Mask>& silhouettes, const ReconstructOptions& o) {
    absl::StatusOr<VoxelGrid> hull = CarveVisualHull(cameras, silhouettes, o.hull);
    EXPECT_TRUE(hull.ok()) << hull.status();
    return hull.ok() ? HullVolumeIoU(*hull, set_->truth_mesh) : 0.0;
  }
  static SimulatedFrameSet* set_;
  static double good_iou_;
};
SimulatedFrameSet* StudioTruth::set_ = nullptr;
double StudioTruth::good_iou_ = 0;

TEST_F(StudioTruth, ShadowRemovalKeepsTheShadowOutOfTheSilhouettes) {
  for (bool remove : {true, false}) {
    SegmentationOptions o;
    o.remove_shadows = remove;
    double iou = 0;
    for (size_t c = 0; c < set_->cameras.size(); ++c) {
      absl::StatusOr<Mask> m = SegmentForeground(set_->images[c], set_->backgrounds[c], o, set_->cameras[c].id);
      ASSERT_TRUE(m.ok());
      iou += MaskIoU(*m, set_->truth_silhouettes[c]) / set_->cameras.size();
    }
    if (remove) {
      EXPECT_GT(iou, 0.98);
    } else {
      EXPECT_LT(iou, 0.9);  // the floor shadow is taken for the actor
    }
  }
}

TEST_F(StudioTruth, HullMatchesTheTrueActor) {
  // The visual hull of this walking body is larger than the body: the gaps between legs and
  // between arms and torso are hidden in most views (the body's rounded parts are each nearly
  // their own hull, ConvexActorsHullIsTight): IoU ~0.91 at 10 and 20 mm (ave-bench studio), the
  // same as strict carving since no camera is bad here. The boxes actor scored ~0.83.
  std::printf("frame set 3, 20 mm: volume IoU %.4f\n", good_iou_);
  EXPECT_GT(good_iou_, 0.88);
  ReconstructOptions strict = Options20mm();
  strict.hull.max_background_votes = 0;
  absl::StatusOr<FrameSetResult> r = ReconstructFrameSet(set_->cameras, set_->images, set_->backgrounds, strict);
  ASSERT_TRUE(r.ok());
  EXPECT_GT(HullVolumeIoU(r->hull, set_->truth_mesh), 0.88);
  const double chamfer = ChamferMm(r->surface, set_->truth_mesh);
  std::printf("strict: Chamfer %.2f mm\n", chamfer);
  EXPECT_LT(chamfer, 8.0);
  // Textured: every vertex has uv in the atlas.
  ASSERT_EQ(r->textured.uv.size(), r->textured.positions_m.size());
  for (const Eigen::Vector2f& uv : r->textured.uv) ASSERT_TRUE(uv.x() >= 0 && uv.x() <= 1 && uv.y() >= 0 && uv.y() <= 1);
}

// The same frame of the boxes actor (same skeleton and walk): each box grows wedges between the
// ring's views that the body's rounded parts do not, so from the true silhouettes its hull is
// looser (ave-bench studio at 10 mm: ~0.84 against the body's ~0.92).
TEST_F(StudioTruth, BoxesActorsHullIsLooserThanTheBodys) {
  absl::StatusOr<SimulatedFrameSet> boxes = SimulateStudioFrameSet(3, 0, sim::StudioActor::kBoxes);
  ASSERT_TRUE(boxes.ok()) << boxes.status();
  EXPECT_EQ(boxes->truth_mesh.TriangleCount(), 13u * 12u);
  HullOptions o = Options20mm().hull;
  o.max_background_votes = 0;
  absl::StatusOr<VoxelGrid> box_hull = CarveVisualHull(boxes->cameras, boxes->truth_silhouettes, o);
  ASSERT_TRUE(box_hull.ok());
  const double box_iou = HullVolumeIoU(*box_hull, boxes->truth_mesh), body_iou = IoU(set_->cameras, set_->truth_silhouettes, Options20mm());
  std::printf("hull of the true silhouettes, 20 mm: body %.4f, boxes %.4f\n", body_iou, box_iou);
  EXPECT_GT(body_iou, box_iou + 0.04);
  EXPECT_GT(box_iou, 0.78);
}

TEST_F(StudioTruth, OneEmptyOrFullSilhouetteIsTolerated) {
  std::vector<Mask> masks;
  for (size_t c = 0; c < set_->cameras.size(); ++c) {
    absl::StatusOr<Mask> m = SegmentForeground(set_->images[c], set_->backgrounds[c], {}, set_->cameras[c].id);
    ASSERT_TRUE(m.ok());
    masks.push_back(*m);
  }
  const ReconstructOptions o = Options20mm();
  std::vector<Mask> bad = masks;
  std::fill(bad[4].data.begin(), bad[4].data.end(), 0);  // ring04 lost the actor
  EXPECT_GT(IoU(set_->cameras, bad, o), good_iou_ - 0.01);
  std::fill(bad[4].data.begin(), bad[4].data.end(), 255);  // ring04 all foreground
  EXPECT_GT(IoU(set_->cameras, bad, o), good_iou_ - 0.05);
}

TEST_F(StudioTruth, ActorPartlyOutsideOneCameraStillCarves) {
  // ring02's image cropped through the middle of the actor (the camera's width and principal
  // point changed to match): half the actor is outside its view.
  std::vector<StudioCameraModel> cameras = set_->cameras;
  std::vector<Mask> masks = set_->truth_silhouettes;
  StudioCameraModel& cam = cameras[2];
  const int w = cam.intrinsics.width, h = cam.intrinsics.height;
  int umin = w, umax = 0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      if (masks[2].data[static_cast<size_t>(v) * w + u]) umin = std::min(umin, u), umax = std::max(umax, u);
  const int centre = (umin + umax) / 2;
  const bool keep_left = centre >= cam.intrinsics.cx;  // keep the side that holds the principal point
  const int c0 = keep_left ? 0 : centre, c1 = keep_left ? centre : w;  // kept columns [c0, c1)
  cam.intrinsics.width = c1 - c0;
  cam.intrinsics.cx -= c0;
  Mask shifted{c1 - c0, h, std::vector<uint8_t>(static_cast<size_t>(c1 - c0) * h, 0)};
  int lost = 0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const uint8_t m = masks[2].data[static_cast<size_t>(v) * w + u];
      if (u >= c0 && u < c1) shifted.data[static_cast<size_t>(v) * (c1 - c0) + u - c0] = m;
      else lost += m != 0;
    }
  ASSERT_GT(lost, 100) << "the actor must leave the image partly";
  masks[2] = shifted;
  const double full = IoU(set_->cameras, set_->truth_silhouettes, Options20mm());
  EXPECT_GT(IoU(cameras, masks, Options20mm()), full - 0.02);
}

TEST_F(StudioTruth, WrongImageSizeNamesTheCamera) {
  std::vector<Image> images = set_->images;
  images[5].width /= 2;
  absl::StatusOr<FrameSetResult> r = ReconstructFrameSet(set_->cameras, images, set_->backgrounds, Options20mm());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find(set_->cameras[5].id), std::string::npos) << r.status();
}

TEST_F(StudioTruth, PhotoCarveRemovesAFloatingSlabAndKeepsTheActor) {
  // The hull of the true silhouettes at 20 mm plus a slab no silhouette has (hung 0.3 m in front
  // of the chest): the cameras that see the slab see different things through it, so space
  // carving removes it. The boxes actor's edges were photo-inconsistent too (two faces of
  // different shading meet there), so each pass also eroded them (ave-bench studio): bounded here.
  HullOptions o = Options20mm().hull;
  o.max_background_votes = 0;
  absl::StatusOr<VoxelGrid> hull = CarveVisualHull(set_->cameras, set_->truth_silhouettes, o);
  ASSERT_TRUE(hull.ok());
  const double iou = HullVolumeIoU(*hull, set_->truth_mesh);
  const sim::StudioActorState actor = sim::StudioActorAt(set_->t_s);
  const Eigen::Vector3d forward(std::cos(actor.heading_rad), std::sin(actor.heading_rad), 0);
  VoxelGrid g = *hull;
  int64_t slab = 0;
  for (int z = 0; z < g.size.z(); ++z)
    for (int y = 0; y < g.size.y(); ++y)
      for (int x = 0; x < g.size.x(); ++x) {
        const Eigen::Vector3d d = g.Center(x, y, z) - actor.ground_m;
        if (std::abs(d.dot(forward) - 0.3) < 0.03 && std::abs(d.z() - 1.2) < 0.1 && std::abs(d.cross(forward).z()) < 0.1) {
          g.occupied[g.Index(x, y, z)] = 1;
          ++slab;
        }
      }
  ASSERT_GT(slab, 50);
  PhotoCarveOptions p;
  p.passes = 4;
  absl::StatusOr<int64_t> carved = PhotoCarve(g, set_->cameras, set_->images, p);
  ASSERT_TRUE(carved.ok()) << carved.status();
  const int64_t removed = *carved;
  int64_t left = 0;
  for (int z = 0; z < g.size.z(); ++z)
    for (int y = 0; y < g.size.y(); ++y)
      for (int x = 0; x < g.size.x(); ++x) {
        const Eigen::Vector3d d = g.Center(x, y, z) - actor.ground_m;
        left += g.occupied[g.Index(x, y, z)] && std::abs(d.dot(forward) - 0.3) < 0.03 && std::abs(d.z() - 1.2) < 0.1 &&
                std::abs(d.cross(forward).z()) < 0.1;
      }
  EXPECT_GE(removed, slab - left);
  EXPECT_LT(left, slab / 4) << left << " of the slab's " << slab << " voxels left";
  EXPECT_GT(HullVolumeIoU(g, set_->truth_mesh), iou - 0.1);
  std::vector<Image> images = set_->images;
  images[6].height /= 2;
  absl::StatusOr<int64_t> bad = PhotoCarve(g, set_->cameras, images, p);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find(set_->cameras[6].id), std::string::npos) << bad.status();
  p.passes = -1;
  EXPECT_FALSE(PhotoCarve(g, set_->cameras, set_->images, p).ok());
}

// --- the measurement itself ---

// The actor is closed convex parts, one after another, sharing no vertex (sim/studio.cc: the
// body's rounded solids or the boxes). An inside test that owes nothing to winding or crossings:
// a convex part is the intersection of its faces' half-spaces, each faced away from the part's
// centroid.
struct HalfSpaces {
  Eigen::AlignedBox3d box;                                 // of the part's vertices
  std::vector<std::pair<Eigen::Vector3d, double>> planes;  // (n, d): inside when n.p < d
};

std::vector<HalfSpaces> PartHalfSpaces(const TriangleMesh& actor) {
  std::vector<HalfSpaces> out;
  for (const TriangleMesh& part : MeshParts(actor)) {
    HalfSpaces h;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3f& p : part.positions) {
      centroid += p.cast<double>() / static_cast<double>(part.positions.size());
      h.box.extend(p.cast<double>());
    }
    for (size_t t = 0; t < part.TriangleCount(); ++t) {
      const Eigen::Vector3d a = part.positions[part.indices[3 * t]].cast<double>();
      Eigen::Vector3d n = (part.positions[part.indices[3 * t + 1]].cast<double>() - a).cross(part.positions[part.indices[3 * t + 2]].cast<double>() - a);
      if (n.norm() < 1e-12) continue;
      n.normalize();
      if (n.dot(centroid - a) > 0) n = -n;
      h.planes.emplace_back(n, n.dot(a));
    }
    out.push_back(std::move(h));
  }
  return out;
}

bool InsideSomePart(const std::vector<HalfSpaces>& parts, const Eigen::Vector3d& p) {
  for (const HalfSpaces& h : parts) {
    if (!h.box.contains(p)) continue;  // the box holds the convex part
    bool inside = true;
    for (size_t i = 0; i < h.planes.size() && inside; ++i) inside = h.planes[i].first.dot(p) < h.planes[i].second;
    if (inside) return true;
  }
  return false;
}

// Signed volume of a closed mesh (positive when wound outward).
double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (size_t t = 0; t < m.TriangleCount(); ++t) {
    v += m.positions[m.indices[3 * t]].cast<double>().dot(
             m.positions[m.indices[3 * t + 1]].cast<double>().cross(m.positions[m.indices[3 * t + 2]].cast<double>())) / 6;
  }
  return v;
}

// Closed and consistently wound: every directed edge once, and its reverse once.
bool ClosedAndConsistent(const TriangleMesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> edges;
  for (size_t t = 0; t < m.TriangleCount(); ++t)
    for (int i = 0; i < 3; ++i) ++edges[{m.indices[3 * t + i], m.indices[3 * t + (i + 1) % 3]}];
  for (const auto& [e, n] : edges) {
    const auto back = edges.find({e.second, e.first});
    if (n != 1 || back == edges.end() || back->second != 1) return false;
  }
  return true;
}

// Convex and wound outward: every vertex on or behind every face's plane, the face's normal by
// its winding (float vertices: 10 um of slack for the coplanar halves of a quad).
double WorstVertexInFront(const TriangleMesh& m) {
  double worst = -1;
  for (size_t t = 0; t < m.TriangleCount(); ++t) {
    const Eigen::Vector3d a = m.positions[m.indices[3 * t]].cast<double>();
    const Eigen::Vector3d n = (m.positions[m.indices[3 * t + 1]].cast<double>() - a).cross(m.positions[m.indices[3 * t + 2]].cast<double>() - a);
    if (n.norm() < 1e-12) continue;
    for (const Eigen::Vector3f& p : m.positions) worst = std::max(worst, n.normalized().dot(p.cast<double>() - a));
  }
  return worst;
}

// A 1-voxel lattice at an odd offset: TruthOccupancy widens it to the truth's box.
VoxelGrid Lattice(double voxel_m) {
  VoxelGrid g;
  g.origin_m = Eigen::Vector3d(-1.2373, -1.1131, -0.0437);
  g.voxel_m = voxel_m;
  g.size = Eigen::Vector3i::Ones();
  g.occupied = {0};
  return g;
}

TEST(StudioTruthMetric, TruthVolumeIsTheUnionOfTheActorsParts) {
  for (const sim::StudioActor kind : {sim::StudioActor::kBody, sim::StudioActor::kBoxes}) {
    for (double t_s : {0.3, 1.4}) {  // legs apart and arms swung, either way
      const std::string what = std::string(sim::StudioActorName(kind)) + " at " + std::to_string(t_s) + " s";
      TriangleMesh actor = sim::StudioActorMesh(t_s, kind);
      const std::vector<TriangleMesh> parts = MeshParts(actor);
      ASSERT_EQ(parts.size(), 13u) << what;  // torso, neck, head, 2 x (thigh, shin, shoe, upper arm, forearm)
      double sum_m3 = 0;
      size_t triangles = 0;
      for (size_t b = 0; b < parts.size(); ++b) {
        EXPECT_TRUE(ClosedAndConsistent(parts[b])) << "part " << b << ", " << what;
        EXPECT_GT(SignedVolume(parts[b]), 0) << "part " << b << " is wound inward, " << what;
        EXPECT_LT(WorstVertexInFront(parts[b]), 1e-5) << "part " << b << " is not convex or not wound outward, " << what;
        sum_m3 += std::abs(SignedVolume(parts[b]));
        triangles += parts[b].TriangleCount();
      }
      ASSERT_EQ(triangles, actor.TriangleCount()) << what;
      const std::vector<HalfSpaces> half_spaces = PartHalfSpaces(actor);
      const VoxelGrid truth = TruthOccupancy(Lattice(0.015), actor);
      int64_t count = 0, wrong = 0;
      for (int z = 0; z < truth.size.z(); ++z)
        for (int y = 0; y < truth.size.y(); ++y)
          for (int x = 0; x < truth.size.x(); ++x) {
            const bool in = truth.occupied[truth.Index(x, y, z)] != 0;
            count += in;
            wrong += in != InsideSomePart(half_spaces, truth.Center(x, y, z));
          }
      EXPECT_EQ(wrong, 0) << what;
      // The parts overlap (hips, shoulders, neck; the body's also at knees and elbows): their
      // union is smaller than their sum, and the voxel count is that union's volume to within
      // the voxels' sampling.
      const double union_m3 = static_cast<double>(count) * std::pow(truth.voxel_m, 3);
      EXPECT_LT(union_m3, sum_m3 - 0.001) << what;
      EXPECT_GT(union_m3, 0.8 * sum_m3) << what;
      // One part wound inward and overlapping another (the first, a thigh, into the torso's hip
      // region) is still inside: the same occupancy.
      TriangleMesh flipped = actor;
      for (size_t t = 0; t < parts[0].TriangleCount(); ++t) std::swap(flipped.indices[3 * t + 1], flipped.indices[3 * t + 2]);
      EXPECT_LT(SignedVolume(MeshParts(flipped)[0]), 0);
      EXPECT_EQ(TruthOccupancy(Lattice(0.015), flipped).occupied, truth.occupied) << what;
      // The truth scored against itself.
      EXPECT_DOUBLE_EQ(HullVolumeIoU(truth, actor), 1.0);
    }
  }
}

// Share of the truth's voxels the hull holds (1: the hull contains the truth, as it must).
double Recall(const VoxelGrid& hull, const TriangleMesh& truth) {
  const VoxelGrid t = TruthOccupancy(hull, truth);
  const Eigen::Vector3i shift = ((hull.origin_m - t.origin_m) / hull.voxel_m).array().round().cast<int>();
  int64_t in = 0, held = 0;
  for (int z = 0; z < t.size.z(); ++z)
    for (int y = 0; y < t.size.y(); ++y)
      for (int x = 0; x < t.size.x(); ++x) {
        if (!t.occupied[t.Index(x, y, z)]) continue;
        ++in;
        const Eigen::Vector3i g = Eigen::Vector3i(x, y, z) - shift;
        held += (g.array() >= 0).all() && (g.array() < hull.size.array()).all() && hull.occupied[hull.Index(g.x(), g.y(), g.z())];
      }
  return in ? static_cast<double>(held) / static_cast<double>(in) : 0.0;
}

TEST_F(StudioTruth, ConvexActorsHullIsTight) {
  // A smooth convex actor is its own visual hull up to the views' polygon (14 views: < 1 % for a
  // cylinder): it must score close to 1, else the carve's bounds, voxel centres, projection or the
  // metric are off. A box is convex too but its hull is not tight: between two of the 13 ring
  // directions (13.8 deg apart) each face grows a wedge up to L tan(6.9 deg) / 2 high, ~12 % of
  // its volume at this yaw (2D construction, docs/BENCHMARKS.md), whatever its size; it must
  // still hold the whole box.
  const struct {
    const char* name;
    TriangleMesh mesh;
    double min_iou, max_iou, max_chamfer_mm;
  } actors[] = {
      {"cylinder r 0.17 m", UprightPrism({-0.3, 0.45}, 0.17, 1.75, 48, 0), 0.97, 1.0, 3.0},
      {"box 0.34 x 0.34 x 1.7 m", UprightPrism({0.6, 0.1}, 0.24, 1.7, 4, 0.4), 0.86, 0.92, 12.0},
  };
  for (const auto& a : actors) {
    std::vector<Mask> masks;
    for (const StudioCameraModel& cam : set_->cameras) masks.push_back(RenderSilhouette(cam, a.mesh));
    for (int k : {0, 1}) {
      HullOptions o;
      o.voxel_m = 0.01;
      o.max_background_votes = k;
      absl::StatusOr<VoxelGrid> hull = CarveVisualHull(set_->cameras, masks, o);
      ASSERT_TRUE(hull.ok()) << hull.status();
      const double iou = HullVolumeIoU(*hull, a.mesh);
      absl::StatusOr<SurfaceMesh> surface = ExtractSurface(*hull, {});
      ASSERT_TRUE(surface.ok());
      const double chamfer = ChamferMm(*surface, a.mesh);
      std::printf("%s, K = %d: IoU %.4f, recall %.4f, Chamfer %.2f mm, hull %.4f m3\n", a.name, k, iou, Recall(*hull, a.mesh), chamfer,
                  hull->Count() * 1e-6);
      EXPECT_GT(iou, a.min_iou) << a.name << ", K = " << k;
      EXPECT_LT(iou, a.max_iou) << a.name << ", K = " << k;
      EXPECT_GT(Recall(*hull, a.mesh), 0.99) << a.name << ", K = " << k;
      EXPECT_LT(chamfer, a.max_chamfer_mm) << a.name << ", K = " << k;
    }
  }
}

}  // namespace
}  // namespace ave::studio::testing
