#include "fusion_server/core/auth.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave {
namespace {

using ::testing::HasSubstr;

TEST(Auth, HashToken_IsSha256Hex) {
  // FIPS 180-2 test vector.
  EXPECT_EQ(HashToken("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(HashToken("").size(), 64u);
}

TEST(Auth, NewRandomToken_IsLongAndDistinct) {
  auto a = NewRandomToken(), b = NewRandomToken();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->size(), 64u);
  EXPECT_NE(*a, *b);
}

TEST(Auth, Registry_UnknownEmptyAndRevokedTokensAreUnauthenticated) {
  TokenRegistry registry;
  registry.Add(HashToken("s1"), {Role::kSensor, "cam1"});
  EXPECT_TRUE(registry.Authenticate("s1").ok());
  EXPECT_TRUE(absl::IsUnauthenticated(registry.Authenticate("s2").status()));
  EXPECT_TRUE(absl::IsUnauthenticated(registry.Authenticate("").status()));
  EXPECT_TRUE(absl::IsUnauthenticated(registry.Authenticate(std::string(5000, 'x')).status()));
  EXPECT_EQ(registry.Revoke(HashToken("s1").substr(0, 12)), 1);
  EXPECT_TRUE(absl::IsUnauthenticated(registry.Authenticate("s1").status()));
  EXPECT_EQ(registry.Revoke(""), 0);
}

TEST(Auth, Authorize_EachRoleIsRefusedOutsideItsRights) {
  const Principal sensor{Role::kSensor, "cam1", "aaaa"};
  const Principal fleet{Role::kSensor, "", "bbbb", true};
  const Principal viewer{Role::kViewer, "", "cccc"};
  const Principal admin{Role::kAdmin, "", "dddd"};

  EXPECT_TRUE(Authorize(sensor, Action::kStream, "cam1").ok());
  const absl::Status other_camera = Authorize(sensor, Action::kStream, "cam2");
  EXPECT_TRUE(absl::IsPermissionDenied(other_camera));
  EXPECT_THAT(std::string(other_camera.message()), HasSubstr("bound to camera 'cam1'"));
  EXPECT_THAT(std::string(other_camera.message()), HasSubstr("'cam2'"));
  EXPECT_TRUE(Authorize(fleet, Action::kStream, "cam9").ok());
  for (Action a : {Action::kSubscribe, Action::kReadModel, Action::kManageCameras, Action::kManageTokens}) {
    EXPECT_TRUE(absl::IsPermissionDenied(Authorize(sensor, a))) << ActionName(a);
  }

  EXPECT_TRUE(Authorize(viewer, Action::kSubscribe).ok());
  EXPECT_TRUE(Authorize(viewer, Action::kReadModel).ok());
  for (Action a : {Action::kStream, Action::kManageCameras, Action::kManageTokens}) {
    const absl::Status s = Authorize(viewer, a, "cam1");
    EXPECT_TRUE(absl::IsPermissionDenied(s)) << ActionName(a);
    EXPECT_THAT(std::string(s.message()), HasSubstr("role viewer"));
  }

  for (Action a : {Action::kSubscribe, Action::kReadModel, Action::kManageCameras, Action::kManageTokens}) {
    EXPECT_TRUE(Authorize(admin, a).ok()) << ActionName(a);
  }
  EXPECT_TRUE(absl::IsPermissionDenied(Authorize(admin, Action::kStream, "cam1")));
}

TEST(Auth, ParseRole_NamesTheBadValue) {
  EXPECT_EQ(*ParseRole("admin"), Role::kAdmin);
  EXPECT_THAT(std::string(ParseRole("root").status().message()), HasSubstr("'root'"));
}

}  // namespace
}  // namespace ave
