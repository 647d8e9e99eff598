#pragma once
// Internal to ave_render: the avatar pass (issue 17, i4D §5). Each avatar sequence is uploaded
// once (all frames in one vertex and one index buffer, their atlases as the layers of one texture
// array); each person is one instance (model matrix) and is drawn with the other instances that
// show the same frame of the same sequence in one instanced draw. Avatars go into the G-buffer
// like the other dynamic models (so projected video lands on them, or, with video_on_people off,
// is kept off them) and into the projectors' dynamic shadow maps; their boxes join the dynamic
// models' bounds (DynamicModels::SetAvatarBounds) for the view cache and the shadow volumes.
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "model_store/avatar/avatar_sequence.h"
#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

class AvatarPass {
 public:
  static absl::StatusOr<std::unique_ptr<AvatarPass>> Create();

  // Uploads every frame of `sequence` (replacing one of the same name). InvalidArgument naming the
  // sequence, frame and field when it breaks avatar_sequence.h's contract.
  absl::Status SetSequence(const avatar::AvatarSequence& sequence);
  bool HasSequence(const std::string& name) const { return sequences_.count(name) > 0; }
  // The people; an instance of a sequence not uploaded is an error naming it. An unchanged list
  // keeps version().
  absl::Status SetInstances(const std::vector<AvatarInstance>& instances);

  // The instances with their own program, into the bound framebuffer: the G-buffer (colour,
  // normal with the video flag) or a depth-only shadow map. Leaves its program and VAO bound.
  void Draw(const Eigen::Matrix4d& clip_from_local, const RendererOptions& options, bool receive_video) const;

  // Per instance, a box around its sequence's frames at any heading (local frame).
  const std::vector<Bounds>& instance_bounds() const { return instance_bounds_; }
  uint64_t version() const { return version_; }
  size_t instance_count() const { return instance_count_; }

 private:
  struct Sequence {
    VertexArray vao = VertexArray::Create();
    GlBuffer vertices = GlBuffer::Create(), indices = GlBuffer::Create();
    Texture atlases = Texture::Create();
    struct Range {
      GLsizei first_index, index_count;
      GLint base_vertex;
    };
    std::vector<Range> frames;
    double reach_m = 0, height_m = 0;  // horizontal radius and top of every frame, avatar frame
  };
  struct DrawCall {
    const Sequence* sequence;
    int frame;
    GLint first_instance;
    GLsizei count;
  };
  explicit AvatarPass(Program program) : program_(std::move(program)) {}

  Program program_;
  std::map<std::string, std::unique_ptr<Sequence>> sequences_;
  GlBuffer instance_buffer_ = GlBuffer::Create();
  std::vector<float> instance_matrices_;  // 16 floats per instance, in draw order
  std::vector<DrawCall> draws_;
  std::vector<Bounds> instance_bounds_;
  size_t instance_count_ = 0;
  uint64_t version_ = 1;
};

}  // namespace ave::viewer::internal
