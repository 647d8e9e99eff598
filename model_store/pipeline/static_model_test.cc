// The static-model pipeline's options and refusals; the campus "done when" (simulated survey ->
// LAS -> pipeline -> store, scored against truth) is tests/truth/static_model_truth_test.cc.
#include "model_store/pipeline/static_model.h"

#include <gtest/gtest.h>

namespace ave::model {
namespace {

TEST(StaticModel, BadOptionsAndEmptyCloudsAreRefusedWithAReason) {
  StaticModelOptions options;
  options.resolution_m = 0;
  EXPECT_NE(options.Check().find("resolution_m"), std::string::npos);
  PointCloud cloud;
  cloud.xyz.emplace_back(0.f, 0.f, 0.f);
  EXPECT_FALSE(BuildStaticModel(cloud, options).ok());
  EXPECT_FALSE(BuildStaticModel(PointCloud{}, StaticModelOptions{}).ok());
  EXPECT_EQ(ClassCountsJson({2, 2, 1, 6}), "{\"1\":1,\"2\":2,\"6\":1}");
}

}  // namespace
}  // namespace ave::model
