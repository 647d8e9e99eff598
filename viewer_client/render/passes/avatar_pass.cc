#include "viewer_client/render/passes/avatar_pass.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "model_store/avatar/avatar_blob.h"
#include "model_store/geometry/camera.h"

namespace ave::viewer::internal {
namespace {

constexpr GLint kAtlasUnit = 9;  // beside the deferred passes' units (gl_util.h)

struct AvatarVertex {
  float position[3];
  float normal[3];
  float uv[2];
};

// The frame of a cycle of `count` frames at `phase_cycles` (wrapped into [0, 1)).
int FrameAt(double phase_cycles, size_t count) {
  if (count <= 1 || !std::isfinite(phase_cycles)) return 0;
  const double wrapped = phase_cycles - std::floor(phase_cycles);
  return std::min(static_cast<int>(count) - 1, static_cast<int>(wrapped * static_cast<double>(count)));
}

// avatar_blob.h's check (the contract), then what a texture array needs on this GL.
std::string CheckSequence(const avatar::AvatarSequence& s) {
  if (std::string why = avatar::CheckAvatarSequence(s); !why.empty()) return why;
  GLint max_side = 0, max_layers = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_side);
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
  if (static_cast<GLint>(s.frames.size()) > max_layers) {
    return "has " + std::to_string(s.frames.size()) + " frames, more than this GL's " + std::to_string(max_layers) +
           " texture array layers";
  }
  for (size_t i = 0; i < s.frames.size(); ++i) {
    const avatar::AvatarFrame& f = s.frames[i];
    if (f.atlas_width <= 0 || f.atlas_height <= 0 || f.atlas_width > max_side || f.atlas_height > max_side) {
      return "frames[" + std::to_string(i) + "].atlas is " + std::to_string(f.atlas_width) + "x" +
             std::to_string(f.atlas_height) + ": the renderer needs 1.." + std::to_string(max_side) + " per side";
    }
  }
  return {};
}

}  // namespace

absl::StatusOr<std::unique_ptr<AvatarPass>> AvatarPass::Create() {
  absl::StatusOr<Program> program = Program::Build(
      "shaders/avatar.vert.glsl", "shaders/avatar.frag.glsl", "",
      {"u_clip_from_local", "u_atlas", "u_layer", "u_sun_direction", "u_ambient", "u_diffuse", "u_receive_video"});
  if (!program.ok()) return program.status();
  return std::unique_ptr<AvatarPass>(new AvatarPass(*std::move(program)));
}

absl::Status AvatarPass::SetSequence(const avatar::AvatarSequence& sequence) {
  if (std::string why = CheckSequence(sequence); !why.empty()) {
    return absl::InvalidArgumentError("avatar sequence '" + sequence.name + "': " + why);
  }
  auto gpu = std::make_unique<Sequence>();
  int atlas_w = 0, atlas_h = 0;
  for (const auto& f : sequence.frames) atlas_w = std::max(atlas_w, f.atlas_width), atlas_h = std::max(atlas_h, f.atlas_height);
  std::vector<AvatarVertex> vertices;
  std::vector<uint32_t> indices;
  for (const avatar::AvatarFrame& f : sequence.frames) {
    gpu->frames.push_back({static_cast<GLsizei>(indices.size()), static_cast<GLsizei>(f.indices.size()),
                           static_cast<GLint>(vertices.size())});
    // Every layer is atlas_w x atlas_h; a smaller atlas fills its top-left corner.
    const float su = static_cast<float>(f.atlas_width) / atlas_w, sv = static_cast<float>(f.atlas_height) / atlas_h;
    for (size_t k = 0; k < f.positions_m.size(); ++k) {
      const Eigen::Vector3f& p = f.positions_m[k];
      const Eigen::Vector3f& n = f.normals[k];
      vertices.push_back({{p.x(), p.y(), p.z()}, {n.x(), n.y(), n.z()}, {f.uv[k].x() * su, f.uv[k].y() * sv}});
      gpu->reach_m = std::max(gpu->reach_m, static_cast<double>(p.head<2>().norm()));
      gpu->height_m = std::max(gpu->height_m, static_cast<double>(p.z()));
    }
    indices.insert(indices.end(), f.indices.begin(), f.indices.end());
  }
  glBindVertexArray(gpu->vao);
  glBindBuffer(GL_ARRAY_BUFFER, gpu->vertices);
  glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(AvatarVertex), vertices.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, gpu->indices);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, indices.size() * sizeof(uint32_t), indices.data(), GL_STATIC_DRAW);
  const GLsizei stride = sizeof(AvatarVertex);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(AvatarVertex, position)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(AvatarVertex, normal)));
  glEnableVertexAttribArray(2);
  glVertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(AvatarVertex, uv)));
  for (GLuint c = 0; c < 4; ++c) {  // the instance's model matrix, one column per attribute
    glEnableVertexAttribArray(3 + c);
    glVertexAttribDivisor(3 + c, 1);
  }
  glBindVertexArray(0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, gpu->atlases);
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGB8, atlas_w, atlas_h, static_cast<GLsizei>(sequence.frames.size()), 0,
               GL_RGB, GL_UNSIGNED_BYTE, nullptr);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  for (size_t i = 0; i < sequence.frames.size(); ++i) {
    const avatar::AvatarFrame& f = sequence.frames[i];
    glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, static_cast<GLint>(i), f.atlas_width, f.atlas_height, 1, GL_RGB,
                    GL_UNSIGNED_BYTE, f.atlas_rgb.data());
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  sequences_[sequence.name] = std::move(gpu);
  draws_.clear();  // instances pointed at the replaced sequence: SetInstances again
  instance_count_ = 0;
  instance_matrices_.clear();
  ++version_;
  return CheckGl("SetAvatarSequence");
}

absl::Status AvatarPass::SetInstances(const std::vector<AvatarInstance>& instances) {
  struct Placed {
    const Sequence* sequence;
    int frame;
    GlMatrix local_from_avatar;
  };
  std::vector<Placed> placed;
  placed.reserve(instances.size());
  std::vector<Bounds> bounds(instances.size());
  for (size_t k = 0; k < instances.size(); ++k) {
    const AvatarInstance& a = instances[k];
    auto it = sequences_.find(a.sequence);
    if (it == sequences_.end()) {
      return absl::InvalidArgumentError("SetAvatars: avatar " + std::to_string(k) + " uses sequence '" + a.sequence +
                                        "', which was not given to SetAvatarSequence");
    }
    if (!a.base.allFinite() || !std::isfinite(a.heading_rad)) {
      return absl::InvalidArgumentError("SetAvatars: avatar " + std::to_string(k) + " needs a finite base and heading");
    }
    const Sequence& s = *it->second;
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    const double c = std::cos(a.heading_rad), sn = std::sin(a.heading_rad);
    m.topLeftCorner<2, 2>() << c, -sn, sn, c;
    m.topRightCorner<3, 1>() = a.base;
    placed.push_back({&s, FrameAt(a.phase_cycles, s.frames.size()), ToGlArray(m)});
    bounds[k].Add(a.base - Eigen::Vector3d(s.reach_m, s.reach_m, 0.05));
    bounds[k].Add(a.base + Eigen::Vector3d(s.reach_m, s.reach_m, s.height_m));
  }
  std::stable_sort(placed.begin(), placed.end(), [](const Placed& a, const Placed& b) {
    return a.sequence != b.sequence ? a.sequence < b.sequence : a.frame < b.frame;
  });
  std::vector<float> matrices;
  matrices.reserve(placed.size() * 16);
  std::vector<DrawCall> draws;
  for (size_t k = 0; k < placed.size(); ++k) {
    if (draws.empty() || draws.back().sequence != placed[k].sequence || draws.back().frame != placed[k].frame) {
      draws.push_back({placed[k].sequence, placed[k].frame, static_cast<GLint>(k), 0});
    }
    ++draws.back().count;
    matrices.insert(matrices.end(), placed[k].local_from_avatar.begin(), placed[k].local_from_avatar.end());
  }
  bool same = matrices == instance_matrices_ && draws.size() == draws_.size();
  for (size_t k = 0; same && k < draws.size(); ++k) {
    same = draws[k].sequence == draws_[k].sequence && draws[k].frame == draws_[k].frame && draws[k].count == draws_[k].count;
  }
  if (same) return absl::OkStatus();
  glBindBuffer(GL_ARRAY_BUFFER, instance_buffer_);
  glBufferData(GL_ARRAY_BUFFER, matrices.size() * sizeof(float), matrices.data(), GL_DYNAMIC_DRAW);
  instance_matrices_ = std::move(matrices);
  draws_ = std::move(draws);
  instance_bounds_ = std::move(bounds);
  instance_count_ = instances.size();
  ++version_;
  return CheckGl("SetAvatars");
}

void AvatarPass::Draw(const Eigen::Matrix4d& clip_from_local, const RendererOptions& options, bool receive_video) const {
  if (draws_.empty()) return;
  glUseProgram(program_.id);
  const Uniforms& u = program_.u;
  glUniformMatrix4fv(u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(clip_from_local).data());
  const Eigen::Vector3f sun = options.sun_direction.normalized();
  glUniform3f(u["u_sun_direction"], sun.x(), sun.y(), sun.z());
  glUniform1f(u["u_ambient"], options.ambient);
  glUniform1f(u["u_diffuse"], options.diffuse);
  glUniform1f(u["u_receive_video"], receive_video ? 1.0f : 0.0f);
  glUniform1i(u["u_atlas"], kAtlasUnit);
  const Sequence* bound = nullptr;
  for (const DrawCall& d : draws_) {
    if (d.sequence != bound) {
      bound = d.sequence;
      glBindVertexArray(bound->vao);
      BindTexture(kAtlasUnit, GL_TEXTURE_2D_ARRAY, bound->atlases);
    }
    glBindBuffer(GL_ARRAY_BUFFER, instance_buffer_);
    for (GLuint c = 0; c < 4; ++c) {
      const size_t offset = (static_cast<size_t>(d.first_instance) * 16 + 4 * c) * sizeof(float);
      glVertexAttribPointer(3 + c, 4, GL_FLOAT, GL_FALSE, 16 * sizeof(float), reinterpret_cast<void*>(offset));
    }
    glUniform1f(u["u_layer"], static_cast<float>(d.frame));
    const Sequence::Range& r = bound->frames[d.frame];
    glDrawElementsInstancedBaseVertex(GL_TRIANGLES, r.index_count, GL_UNSIGNED_INT,
                                      reinterpret_cast<void*>(static_cast<size_t>(r.first_index) * sizeof(uint32_t)),
                                      d.count, r.base_vertex);
  }
  glBindVertexArray(0);
}

}  // namespace ave::viewer::internal
