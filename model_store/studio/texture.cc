#include "model_store/studio/texture.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "model_store/studio/raster.h"

namespace ave::studio {
namespace {

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

struct Chart {
  int camera = -1;
  std::vector<int> triangles;
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // image pixel rectangle (inclusive)
  int ax = 0, ay = 0;                  // its place in the atlas
  int Width() const { return x1 - x0 + 1; }
  int Height() const { return y1 - y0 + 1; }
};

}  // namespace

std::string TextureOptions::Check() const {
  if (!std::isfinite(depth_tolerance_m) || depth_tolerance_m < 0) return "depth_tolerance_m must be finite and >= 0";
  if (chart_padding_px < 0 || chart_padding_px > 16) return "chart_padding_px must be in [0, 16]";
  if (max_atlas_width < 64 || max_atlas_width > 16384) return "max_atlas_width must be in [64, 16384]";
  return {};
}

absl::StatusOr<avatar::AvatarFrame> TextureMesh(const SurfaceMesh& mesh, const std::vector<StudioCameraModel>& cameras,
                                                const std::vector<Image>& images, const TextureOptions& options,
                                                TextureStats* stats) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("texture options: " + why);
  if (cameras.size() != images.size()) {
    return absl::InvalidArgumentError("texture: " + std::to_string(cameras.size()) + " cameras but " + std::to_string(images.size()) + " images");
  }
  for (size_t c = 0; c < cameras.size(); ++c) {
    const PinholeIntrinsics& k = cameras[c].intrinsics;
    if (images[c].width != k.width || images[c].height != k.height || images[c].bgr.size() != static_cast<size_t>(k.width) * k.height * 3) {
      return absl::InvalidArgumentError("camera " + cameras[c].id + ": image is " + std::to_string(images[c].width) + "x" +
                                        std::to_string(images[c].height) + ", the camera " + std::to_string(k.width) + "x" + std::to_string(k.height));
    }
  }
  const size_t n_tri = mesh.TriangleCount();
  TextureStats st;
  st.triangles_per_camera.assign(cameras.size(), 0);
  // Best camera per triangle.
  std::vector<int> label(n_tri, -1);
  std::vector<double> best(n_tri, 0.0), best_unseen(n_tri, 0.0);
  std::vector<int> label_unseen(n_tri, -1);
  std::vector<std::vector<Eigen::Vector2f>> pixel(cameras.size());  // every vertex projected per camera
  for (size_t c = 0; c < cameras.size(); ++c) {
    const StudioCameraModel& cam = cameras[c];
    const PinholeIntrinsics& k = cam.intrinsics;
    const Rigid3d camera_from_world = cam.world_from_camera.Inverse();
    const RasterBuffers depth = Rasterize(cam, mesh.positions_m, mesh.indices);
    std::vector<Eigen::Vector2f>& px = pixel[c];
    std::vector<float> z(mesh.positions_m.size());
    px.resize(mesh.positions_m.size());
    for (size_t i = 0; i < mesh.positions_m.size(); ++i) {
      const Eigen::Vector3d q = camera_from_world * mesh.positions_m[i].cast<double>();
      z[i] = static_cast<float>(q.z());
      px[i] = q.z() > 0.05 ? Eigen::Vector2f(static_cast<float>(k.fx * q.x() / q.z() + k.cx), static_cast<float>(k.fy * q.y() / q.z() + k.cy))
                           : Eigen::Vector2f(-1e9f, -1e9f);
    }
    const Eigen::Vector3f eye = cam.world_from_camera.translation.cast<float>();
    for (size_t t = 0; t < n_tri; ++t) {
      const uint32_t i0 = mesh.indices[3 * t], i1 = mesh.indices[3 * t + 1], i2 = mesh.indices[3 * t + 2];
      const Eigen::Vector3f& a = mesh.positions_m[i0];
      const Eigen::Vector3f n = (mesh.positions_m[i1] - a).cross(mesh.positions_m[i2] - a).normalized();
      const Eigen::Vector3f centre = (a + mesh.positions_m[i1] + mesh.positions_m[i2]) / 3.0f;
      const float cos_view = n.dot((eye - centre).normalized());
      if (!(cos_view > 0)) continue;
      bool in_image = true;
      for (uint32_t i : {i0, i1, i2}) {
        in_image = in_image && px[i].x() >= 0.5f && px[i].y() >= 0.5f && px[i].x() <= k.width - 1.5f && px[i].y() <= k.height - 1.5f;
      }
      if (!in_image) continue;
      const Eigen::Vector2f e1 = px[i1] - px[i0], e2 = px[i2] - px[i0];
      const double score = static_cast<double>(cos_view) * 0.5 * std::abs(e1.x() * e2.y() - e1.y() * e2.x());
      if (score > best_unseen[t]) {
        best_unseen[t] = score;
        label_unseen[t] = static_cast<int>(c);
      }
      const Eigen::Vector2f pc = (px[i0] + px[i1] + px[i2]) / 3.0f;
      const int u = static_cast<int>(std::lround(pc.x())), v = static_cast<int>(std::lround(pc.y()));
      const float zc = (z[i0] + z[i1] + z[i2]) / 3.0f;
      if (zc > depth.depth_m[static_cast<size_t>(v) * k.width + u] + options.depth_tolerance_m) continue;  // hidden
      if (score > best[t]) {
        best[t] = score;
        label[t] = static_cast<int>(c);
      }
    }
  }
  for (size_t t = 0; t < n_tri; ++t) {
    if (label[t] < 0) {
      label[t] = label_unseen[t];
      ++st.triangles_unseen;
    }
    if (label[t] >= 0) ++st.triangles_per_camera[label[t]];
  }
  // Charts: triangles sharing a vertex and a camera.
  std::vector<int> parent(n_tri);
  std::iota(parent.begin(), parent.end(), 0);
  {
    std::vector<std::vector<int>> at_vertex(mesh.positions_m.size());
    for (size_t t = 0; t < n_tri; ++t)
      for (int i = 0; i < 3; ++i) at_vertex[mesh.indices[3 * t + i]].push_back(static_cast<int>(t));
    for (const std::vector<int>& tris : at_vertex) {
      for (size_t a = 0; a < tris.size(); ++a) {
        for (size_t b = a + 1; b < tris.size(); ++b) {
          if (label[tris[a]] == label[tris[b]]) parent[Find(parent, tris[a])] = Find(parent, tris[b]);
        }
      }
    }
  }
  std::vector<Chart> charts;
  std::vector<int> chart_of_root(n_tri, -1);
  for (size_t t = 0; t < n_tri; ++t) {
    const int root = Find(parent, static_cast<int>(t));
    if (chart_of_root[root] < 0) {
      chart_of_root[root] = static_cast<int>(charts.size());
      charts.push_back({});
      charts.back().camera = label[t];
      charts.back().x0 = charts.back().y0 = INT32_MAX;
      charts.back().x1 = charts.back().y1 = INT32_MIN;
    }
    Chart& ch = charts[chart_of_root[root]];
    ch.triangles.push_back(static_cast<int>(t));
    if (ch.camera < 0) continue;
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector2f& p = pixel[ch.camera][mesh.indices[3 * t + i]];
      ch.x0 = std::min(ch.x0, static_cast<int>(std::floor(p.x())));
      ch.y0 = std::min(ch.y0, static_cast<int>(std::floor(p.y())));
      ch.x1 = std::max(ch.x1, static_cast<int>(std::ceil(p.x())));
      ch.y1 = std::max(ch.y1, static_cast<int>(std::ceil(p.y())));
    }
  }
  int64_t area = 0;
  int widest = 1;
  for (Chart& ch : charts) {
    if (ch.camera < 0) {  // seen by no camera at all: a small grey patch
      ch.x0 = ch.y0 = 0;
      ch.x1 = ch.y1 = 1;
    } else {
      const int pad = options.chart_padding_px;
      const PinholeIntrinsics& k = cameras[ch.camera].intrinsics;
      ch.x0 = std::max(0, ch.x0 - pad);
      ch.y0 = std::max(0, ch.y0 - pad);
      ch.x1 = std::min(k.width - 1, ch.x1 + pad);
      ch.y1 = std::min(k.height - 1, ch.y1 + pad);
    }
    area += static_cast<int64_t>(ch.Width()) * ch.Height();
    widest = std::max(widest, ch.Width());
  }
  // Shelf packing, tallest first.
  const int atlas_w = std::min(options.max_atlas_width,
                               std::max(widest, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(area) * 1.3) / 64.0)) * 64));
  if (widest > atlas_w) return absl::InternalError("texture: a chart is wider than max_atlas_width");
  std::vector<int> order(charts.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return charts[a].Height() > charts[b].Height(); });
  int x = 0, y = 0, shelf = 0;
  for (int i : order) {
    Chart& ch = charts[i];
    if (x + ch.Width() > atlas_w) {
      x = 0;
      y += shelf;
      shelf = 0;
    }
    ch.ax = x;
    ch.ay = y;
    x += ch.Width();
    shelf = std::max(shelf, ch.Height());
  }
  avatar::AvatarFrame out;
  out.atlas_width = atlas_w;
  out.atlas_height = std::max(1, y + shelf);
  out.atlas_rgb.assign(static_cast<size_t>(out.atlas_width) * out.atlas_height * 3, 128);
  std::vector<int32_t> new_index(mesh.positions_m.size(), -1);
  for (const Chart& ch : charts) {
    if (ch.camera >= 0) {
      const Image& img = images[ch.camera];
      for (int r = 0; r < ch.Height(); ++r) {
        for (int c = 0; c < ch.Width(); ++c) {
          const uint8_t* src = &img.bgr[(static_cast<size_t>(ch.y0 + r) * img.width + ch.x0 + c) * 3];
          uint8_t* dst = &out.atlas_rgb[(static_cast<size_t>(ch.ay + r) * out.atlas_width + ch.ax + c) * 3];
          dst[0] = src[2];
          dst[1] = src[1];
          dst[2] = src[0];
        }
      }
    }
    // This chart's own copies of its vertices.
    std::vector<uint32_t> touched;
    for (int t : ch.triangles) {
      for (int i = 0; i < 3; ++i) {
        const uint32_t v = mesh.indices[3 * static_cast<size_t>(t) + i];
        if (new_index[v] < 0) {
          new_index[v] = static_cast<int32_t>(out.positions_m.size());
          touched.push_back(v);
          out.positions_m.push_back(mesh.positions_m[v]);
          out.normals.push_back(mesh.normals.size() == mesh.positions_m.size() ? mesh.normals[v] : Eigen::Vector3f::UnitZ());
          Eigen::Vector2f tex(ch.ax + 1.0f, ch.ay + 1.0f);  // centre of the grey patch
          if (ch.camera >= 0) {
            const Eigen::Vector2f& p = pixel[ch.camera][v];
            tex = Eigen::Vector2f(ch.ax + (p.x() - ch.x0) + 0.5f, ch.ay + (p.y() - ch.y0) + 0.5f);
          }
          out.uv.emplace_back(tex.x() / out.atlas_width, tex.y() / out.atlas_height);
        }
        out.indices.push_back(static_cast<uint32_t>(new_index[v]));
      }
    }
    for (uint32_t v : touched) new_index[v] = -1;
  }
  st.charts = static_cast<int>(charts.size());
  if (stats) *stats = std::move(st);
  return out;
}

}  // namespace ave::studio
