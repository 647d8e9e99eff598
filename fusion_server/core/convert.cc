#include "fusion_server/core/convert.h"

namespace ave {

v1::Intrinsics ToProto(const PinholeIntrinsics& k) {
  v1::Intrinsics out;
  out.set_width(k.width);
  out.set_height(k.height);
  out.set_fx(k.fx);
  out.set_fy(k.fy);
  out.set_cx(k.cx);
  out.set_cy(k.cy);
  bool any = false;
  for (double d : k.distortion) any |= d != 0;
  if (any)
    for (double d : k.distortion) out.add_distortion(d);
  return out;
}

PinholeIntrinsics FromProto(const v1::Intrinsics& k) {
  PinholeIntrinsics out;
  out.width = static_cast<int>(std::min<uint32_t>(k.width(), 1u << 30));
  out.height = static_cast<int>(std::min<uint32_t>(k.height(), 1u << 30));
  out.fx = k.fx();
  out.fy = k.fy();
  out.cx = k.cx();
  out.cy = k.cy();
  for (int i = 0; i < std::min(5, k.distortion_size()); ++i) out.distortion[i] = k.distortion(i);
  return out;
}

v1::Pose ToProto(const Rigid3d& p) {
  v1::Pose out;
  out.mutable_position()->set_x(p.translation.x());
  out.mutable_position()->set_y(p.translation.y());
  out.mutable_position()->set_z(p.translation.z());
  out.mutable_orientation()->set_w(p.rotation.w());
  out.mutable_orientation()->set_x(p.rotation.x());
  out.mutable_orientation()->set_y(p.rotation.y());
  out.mutable_orientation()->set_z(p.rotation.z());
  return out;
}

Rigid3d FromProto(const v1::Pose& p) {
  const auto& q = p.orientation();
  return Rigid3d(Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z()),
                 Eigen::Vector3d(p.position().x(), p.position().y(), p.position().z()));
}

void SetMatrix(const Eigen::Matrix4d& m, google::protobuf::RepeatedField<float>* out) {
  out->Clear();
  for (float v : ToGlArray(m)) out->Add(v);
}

Eigen::Matrix4d GetMatrix(const google::protobuf::RepeatedField<float>& m) {
  Eigen::Matrix4d out = Eigen::Matrix4d::Identity();
  if (m.size() != 16) return out;
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) out(r, c) = m.Get(c * 4 + r);
  return out;
}

}  // namespace ave
