// ave-studio: the i4D 4D studio (issue 17, §4-§5) from the files `ave-sim studio` writes
// (docs/SIMULATOR_FORMATS.md) or a real studio laid out the same way.
//   ave-studio --input DIR --out OUTDIR [--voxel-mm 10] [--tolerance 1] [--background auto|plate|median]
// Per frame set: OUTDIR/frame_NNNN.obj + .mtl + .png (studio world, metres, z up); then the walk
// cycle as OUTDIR/walk.avseq (model_store/avatar/avatar_blob.h), the store's avatar sequence form.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "model_store/avatar/avatar_blob.h"
#include "model_store/avatar/walk_cycle.h"
#include "model_store/common/cli.h"
#include "model_store/studio/reconstruct.h"
#include "model_store/studio/studio_io.h"

namespace {

namespace fs = std::filesystem;
using namespace ave::studio;

int Fail(const std::string& what) {
  std::cerr << "ave-studio: " << what << "\n";
  return 1;
}

std::string FramePath(const std::string& dir, const std::string& camera, int frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "image_%04d.png", frame);
  return (fs::path(dir) / camera / name).string();
}

// One image of a camera, checked against the calibration's size.
absl::StatusOr<Image> ReadView(const std::string& path, const StudioCameraModel& camera) {
  absl::StatusOr<Image> image = ReadColourPng(path);
  if (!image.ok()) return absl::Status(image.status().code(), "camera " + camera.id + ": " + std::string(image.status().message()));
  if (image->width != camera.intrinsics.width || image->height != camera.intrinsics.height) {
    return absl::InvalidArgumentError(path + ": camera " + camera.id + " image is " + std::to_string(image->width) + "x" +
                                      std::to_string(image->height) + ", calibration.json says " + std::to_string(camera.intrinsics.width) +
                                      "x" + std::to_string(camera.intrinsics.height));
  }
  return image;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ave-studio: 4D studio reconstruction (visual hull, marching cubes, texture) and the walk cycle"};
  std::string input, out, background = "auto", name = "studio-walk";
  double voxel_mm = 10;
  int tolerance = 1, max_frames = 0;
  bool keep_shadows = false;
  ave::avatar::WalkCycleOptions walk;
  app.add_option("--input", input, "directory from `ave-sim studio` (calibration.json, <camera>/image_NNNN.png)")->required();
  app.add_option("--out", out, "output directory (created)")->required();
  app.add_option("--voxel-mm", voxel_mm, "finest voxel edge in millimetres")->capture_default_str()->check(ave::cli::Range(2.0, 200.0));
  app.add_option("--tolerance", tolerance, "cameras that may call a voxel background without carving it")->capture_default_str()->check(ave::cli::Range(0, 8));
  app.add_option("--background", background, "auto: <camera>/background.png when present, else the per-pixel median of the frames; plate; median")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "plate", "median"}));
  app.add_flag("--keep-shadows", keep_shadows, "no shadow removal (for comparison)");
  app.add_option("--frames", max_frames, "reconstruct only the first N frame sets (0: all)")->check(ave::cli::Range(0, 100000));
  app.add_option("--name", name, "avatar sequence name (unique in the store)")->capture_default_str();
  app.add_option("--min-cycle-s", walk.min_cycle_s, "shortest walk cycle, seconds")->capture_default_str()->check(ave::cli::Range(0.0, 60.0));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-studio")) return *exit_code;

  absl::StatusOr<StudioCalibration> cal = ReadStudioCalibration((fs::path(input) / "calibration.json").string());
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  const int frames = max_frames > 0 ? std::min(max_frames, cal->frames) : cal->frames;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) return Fail(out + ": cannot create (" + ec.message() + ")");

  ReconstructOptions options;
  options.hull.voxel_m = voxel_mm / 1000.0;
  options.hull.max_background_votes = tolerance;
  options.hull.floor_z_m = cal->floor_z_m;
  options.segmentation.remove_shadows = !keep_shadows;

  // Background plates.
  std::vector<Image> backgrounds;
  for (const StudioCameraModel& cam : cal->cameras) {
    const std::string plate = (fs::path(input) / cam.id / "background.png").string();
    const bool use_plate = background == "plate" || (background == "auto" && fs::exists(plate));
    if (use_plate) {
      absl::StatusOr<Image> bg = ReadView(plate, cam);
      if (!bg.ok()) return Fail(std::string(bg.status().message()));
      backgrounds.push_back(*std::move(bg));
      continue;
    }
    std::vector<Image> all;
    for (int f = 0; f < frames; ++f) {
      absl::StatusOr<Image> img = ReadView(FramePath(input, cam.id, f), cam);
      if (!img.ok()) return Fail(std::string(img.status().message()));
      all.push_back(*std::move(img));
    }
    absl::StatusOr<Image> bg = MedianBackground(all, cam.id);
    if (!bg.ok()) return Fail(std::string(bg.status().message()));
    backgrounds.push_back(*std::move(bg));
  }
  std::cerr << "ave-studio: " << cal->cameras.size() << " cameras, " << frames << " frame sets, voxel " << voxel_mm << " mm, background "
            << (background == "median" || (background == "auto" && !fs::exists(fs::path(input) / cal->cameras[0].id / "background.png"))
                    ? "per-pixel median of the frames"
                    : "plates (<camera>/background.png)")
            << ", shadow removal " << (keep_shadows ? "off" : "on") << "\n";

  std::vector<ave::avatar::AvatarFrame> meshes;
  std::vector<Eigen::Vector3d> roots;
  for (int f = 0; f < frames; ++f) {
    std::vector<Image> images;
    for (const StudioCameraModel& cam : cal->cameras) {
      absl::StatusOr<Image> img = ReadView(FramePath(input, cam.id, f), cam);
      if (!img.ok()) return Fail(std::string(img.status().message()));
      images.push_back(*std::move(img));
    }
    absl::StatusOr<FrameSetResult> r = ReconstructFrameSet(cal->cameras, images, backgrounds, options);
    if (!r.ok()) return Fail("frame " + std::to_string(f) + ": " + std::string(r.status().message()));
    if (r->surface.TriangleCount() == 0) return Fail("frame " + std::to_string(f) + ": the visual hull is empty (no actor in the silhouettes?)");
    char stem[32];
    std::snprintf(stem, sizeof(stem), "frame_%04d", f);
    if (absl::Status s = WriteTexturedObj(r->textured, out, stem); !s.ok()) return Fail(std::string(s.message()));
    std::fprintf(stderr, "ave-studio: frame %d/%d: %lld voxels, %zu triangles, %d charts, atlas %dx%d, %.0f ms CPU (hull %.0f, texture %.0f)\n",
                 f + 1, frames, static_cast<long long>(r->hull.Count()), r->surface.TriangleCount(), r->texture_stats.charts,
                 r->textured.atlas_width, r->textured.atlas_height, r->cost.TotalMs(), r->cost.hull_ms, r->cost.texture_ms);
    roots.push_back(ave::avatar::GroundCentroid(r->textured));
    meshes.push_back(std::move(r->textured));
  }
  absl::StatusOr<ave::avatar::WalkCycle> cycle = ave::avatar::FindWalkCycle(meshes, roots, 1.0 / cal->fps, name, walk);
  if (!cycle.ok()) {
    std::cerr << "ave-studio: " << cycle.status().message() << "; writing frame 0 as a statue\n";
    cycle = ave::avatar::FindWalkCycle({meshes[0]}, {roots[0]}, 1.0 / cal->fps, name, walk);
    if (!cycle.ok()) return Fail(std::string(cycle.status().message()));
  }
  const std::string seq_path = (fs::path(out) / "walk.avseq").string();
  if (cycle->sequence.frames.size() == 1) std::cerr << "ave-studio: one frame set: the sequence is a statue (stride 0)\n";
  if (absl::Status s = ave::avatar::WriteAvatarSequenceFile(seq_path, cycle->sequence); !s.ok()) return Fail(std::string(s.message()));
  std::fprintf(stderr, "ave-studio: walk cycle frames %d..%d (%zu frames, shape difference %.1f mm), stride %.3f m, %.2f m/s -> %s\n", cycle->first,
               cycle->end - 1, cycle->sequence.frames.size(), 1000 * cycle->shape_difference_m, cycle->sequence.stride_m,
               cycle->sequence.SpeedMps(), seq_path.c_str());
  return 0;
}
