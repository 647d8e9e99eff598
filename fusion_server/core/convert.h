#pragma once
// Conversions between the wire types (ave.v1) and the shared geometry vocabulary.
#include <string>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"
#include "ave/v1/ave.pb.h"

namespace ave {

v1::Intrinsics ToProto(const PinholeIntrinsics& k);
PinholeIntrinsics FromProto(const v1::Intrinsics& k);

v1::Pose ToProto(const Rigid3d& world_from_camera);
// No validation: callers check with ValidatePose first.
Rigid3d FromProto(const v1::Pose& pose);

// Fills a repeated float field with a column-major GL matrix.
void SetMatrix(const Eigen::Matrix4d& m, google::protobuf::RepeatedField<float>* out);
Eigen::Matrix4d GetMatrix(const google::protobuf::RepeatedField<float>& m);

}  // namespace ave
