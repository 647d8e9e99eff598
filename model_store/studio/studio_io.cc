#include "model_store/studio/studio_io.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_cat.h"
#include "model_store/image/image_decode.h"

namespace ave::studio {
namespace {

absl::StatusOr<double> Number(const nlohmann::json& j, const char* field, const std::string& where) {
  if (!j.contains(field) || !j[field].is_number()) return absl::InvalidArgumentError(where + ": field '" + field + "' missing or not a number");
  const double v = j[field].get<double>();
  if (!std::isfinite(v)) return absl::InvalidArgumentError(where + ": field '" + field + "' is not finite");
  return v;
}

}  // namespace

absl::StatusOr<StudioCalibration> ReadStudioCalibration(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(path + ": cannot open (a studio calibration.json)");
  nlohmann::json j = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return absl::InvalidArgumentError(path + ": not a JSON object");
  if (j.value("format", std::string()) != "ave-studio-calibration-1") {
    return absl::InvalidArgumentError(path + ": field 'format' is not \"ave-studio-calibration-1\"");
  }
  StudioCalibration cal;
  absl::StatusOr<double> fps = Number(j, "fps", path), frames = Number(j, "frames", path);
  if (!fps.ok()) return fps.status();
  if (!frames.ok()) return frames.status();
  if (*fps <= 0) return absl::InvalidArgumentError(path + ": field 'fps' must be > 0");
  if (*frames < 1 || *frames != std::floor(*frames)) return absl::InvalidArgumentError(path + ": field 'frames' must be a whole number >= 1");
  cal.fps = *fps;
  cal.frames = static_cast<int>(*frames);
  if (j.contains("floor_z_m")) {
    absl::StatusOr<double> floor = Number(j, "floor_z_m", path);
    if (!floor.ok()) return floor.status();
    cal.floor_z_m = *floor;
  }
  if (!j.contains("cameras") || !j["cameras"].is_array() || j["cameras"].empty()) {
    return absl::InvalidArgumentError(path + ": field 'cameras' missing or empty");
  }
  for (size_t i = 0; i < j["cameras"].size(); ++i) {
    const nlohmann::json& c = j["cameras"][i];
    std::string where = path + ": cameras[" + std::to_string(i) + "]";
    if (!c.is_object() || !c.contains("id") || !c["id"].is_string() || c["id"].get<std::string>().empty()) {
      return absl::InvalidArgumentError(where + ": field 'id' missing or not a string");
    }
    StudioCameraModel cam;
    cam.id = c["id"].get<std::string>();
    where += " (" + cam.id + ")";
    absl::StatusOr<double> w = Number(c, "width", where), h = Number(c, "height", where), fx = Number(c, "fx", where),
                           fy = Number(c, "fy", where), cx = Number(c, "cx", where), cy = Number(c, "cy", where);
    for (const auto* v : {&w, &h, &fx, &fy, &cx, &cy})
      if (!v->ok()) return v->status();
    cam.intrinsics.width = static_cast<int>(*w);
    cam.intrinsics.height = static_cast<int>(*h);
    cam.intrinsics.fx = *fx;
    cam.intrinsics.fy = *fy;
    cam.intrinsics.cx = *cx;
    cam.intrinsics.cy = *cy;
    if (c.contains("distortion")) {
      if (!c["distortion"].is_array() || c["distortion"].size() != 5) return absl::InvalidArgumentError(where + ": field 'distortion' is not 5 numbers");
      for (int k = 0; k < 5; ++k) {
        if (!c["distortion"][k].is_number() || c["distortion"][k].get<double>() != 0.0) {
          return absl::InvalidArgumentError(where + ": field 'distortion' is not zero; undistort the images first (the studio uses ideal pinholes)");
        }
      }
    }
    if (const std::string why = cam.intrinsics.Check(); !why.empty()) return absl::InvalidArgumentError(where + ": " + why);
    if (!c.contains("world_from_camera") || !c["world_from_camera"].is_object()) {
      return absl::InvalidArgumentError(where + ": field 'world_from_camera' missing");
    }
    const nlohmann::json& pose = c["world_from_camera"];
    const std::string pose_where = where + ".world_from_camera";
    double q[4], t[3];
    const char* qn[4] = {"qw", "qx", "qy", "qz"};
    const char* tn[3] = {"tx", "ty", "tz"};
    for (int k = 0; k < 4; ++k) {
      absl::StatusOr<double> v = Number(pose, qn[k], pose_where);
      if (!v.ok()) return v.status();
      q[k] = *v;
    }
    for (int k = 0; k < 3; ++k) {
      absl::StatusOr<double> v = Number(pose, tn[k], pose_where);
      if (!v.ok()) return v.status();
      t[k] = *v;
    }
    const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (std::abs(quat.norm() - 1.0) > 1e-3) return absl::InvalidArgumentError(pose_where + ": quaternion is not unit length");
    cam.world_from_camera = Rigid3d(quat, Eigen::Vector3d(t[0], t[1], t[2]));
    for (const StudioCameraModel& other : cal.cameras) {
      if (other.id == cam.id) return absl::InvalidArgumentError(where + ": camera id used twice");
    }
    cal.cameras.push_back(std::move(cam));
  }
  return cal;
}

absl::StatusOr<Image> ReadColourPng(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) return absl::NotFoundError(path + ": missing");
  absl::StatusOr<cv::Mat> decoded = image::ReadImageFile(path, image::Channels::kColor);
  if (!decoded.ok()) return absl::NotFoundError(absl::StrCat(decoded.status().message(), " (not a readable image)"));
  const cv::Mat m = *std::move(decoded);
  Image img{m.cols, m.rows, std::vector<uint8_t>(static_cast<size_t>(m.cols) * m.rows * 3)};
  for (int r = 0; r < m.rows; ++r) std::copy_n(m.ptr<uint8_t>(r), m.cols * 3, img.bgr.begin() + static_cast<std::ptrdiff_t>(r) * m.cols * 3);
  return img;
}

absl::StatusOr<Mask> ReadMaskPng(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) return absl::NotFoundError(path + ": missing");
  absl::StatusOr<cv::Mat> decoded = image::ReadImageFile(path, image::Channels::kGray);
  if (!decoded.ok()) return absl::NotFoundError(absl::StrCat(decoded.status().message(), " (not a readable image)"));
  const cv::Mat m = *std::move(decoded);
  Mask mask{m.cols, m.rows, std::vector<uint8_t>(static_cast<size_t>(m.cols) * m.rows)};
  for (int r = 0; r < m.rows; ++r)
    for (int c = 0; c < m.cols; ++c) mask.data[static_cast<size_t>(r) * m.cols + c] = m.at<uint8_t>(r, c) >= 128 ? 255 : 0;
  return mask;
}

absl::Status WritePng(const std::string& path, const Image& image) {
  const cv::Mat m(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data()));
  if (!cv::imwrite(path, m)) return absl::InternalError(path + ": cannot write");
  return absl::OkStatus();
}

absl::Status WriteTexturedObj(const avatar::AvatarFrame& mesh, const std::string& dir, const std::string& stem) {
  const std::string png = stem + ".png", mtl = stem + ".mtl";
  cv::Mat atlas(mesh.atlas_height, mesh.atlas_width, CV_8UC3);
  for (int r = 0; r < mesh.atlas_height; ++r) {
    for (int c = 0; c < mesh.atlas_width; ++c) {
      const uint8_t* s = &mesh.atlas_rgb[(static_cast<size_t>(r) * mesh.atlas_width + c) * 3];
      atlas.at<cv::Vec3b>(r, c) = cv::Vec3b(s[2], s[1], s[0]);
    }
  }
  if (mesh.atlas_width > 0 && !cv::imwrite(dir + "/" + png, atlas)) return absl::InternalError(dir + "/" + png + ": cannot write");
  {
    std::ofstream out(dir + "/" + mtl);
    out << "# ave studio reconstruction\nnewmtl actor\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd " << png << "\n";
    if (!out) return absl::InternalError(dir + "/" + mtl + ": cannot write");
  }
  std::ofstream out(dir + "/" + stem + ".obj");
  out << "# ave studio reconstruction: metres, z up\nmtllib " << mtl << "\nusemtl actor\n";
  char line[128];
  for (const Eigen::Vector3f& p : mesh.positions_m) {
    std::snprintf(line, sizeof(line), "v %.5f %.5f %.5f\n", p.x(), p.y(), p.z());
    out << line;
  }
  for (const Eigen::Vector2f& t : mesh.uv) {
    std::snprintf(line, sizeof(line), "vt %.6f %.6f\n", t.x(), 1.0f - t.y());
    out << line;
  }
  for (const Eigen::Vector3f& n : mesh.normals) {
    std::snprintf(line, sizeof(line), "vn %.4f %.4f %.4f\n", n.x(), n.y(), n.z());
    out << line;
  }
  for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    const uint32_t a = mesh.indices[t] + 1, b = mesh.indices[t + 1] + 1, c = mesh.indices[t + 2] + 1;
    std::snprintf(line, sizeof(line), "f %u/%u/%u %u/%u/%u %u/%u/%u\n", a, a, a, b, b, b, c, c, c);
    out << line;
  }
  if (!out) return absl::InternalError(dir + "/" + stem + ".obj: cannot write");
  return absl::OkStatus();
}

}  // namespace ave::studio
