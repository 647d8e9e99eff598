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

TEST(Auth, ConstantTimeEquals_EqualUnequalAndDifferentLengths) {
  const std::string a = HashToken("a"), b = HashToken("b");
  EXPECT_TRUE(ConstantTimeEquals(a, std::string(a)));
  EXPECT_FALSE(ConstantTimeEquals(a, b));
  std::string last = a;
  last.back() = last.back() == '0' ? '1' : '0';  // differs in the final byte only
  EXPECT_FALSE(ConstantTimeEquals(a, last));
  std::string first = a;
  first.front() = first.front() == '0' ? '1' : '0';
  EXPECT_FALSE(ConstantTimeEquals(a, first));
  EXPECT_FALSE(ConstantTimeEquals(a, a.substr(0, 63)));
  EXPECT_FALSE(ConstantTimeEquals(a.substr(0, 12), a));
  EXPECT_FALSE(ConstantTimeEquals("", a));
  EXPECT_TRUE(ConstantTimeEquals("", ""));
}

TEST(Auth, Registry_TokensSharingTheirPublicIdAreToldApartByTheWholeDigest) {
  // Two entries under one token id (the digest's first 12 hex): the lookup by id is only a first
  // cut; the presented token's whole digest picks the entry.
  const std::string real = HashToken("s1");
  const std::string twin = real.substr(0, 12) + std::string(52, '0');
  TokenRegistry registry;
  registry.Add(twin, {Role::kAdmin});
  registry.Add(real, {Role::kSensor, "cam1"});
  EXPECT_EQ(registry.size(), 2u);
  absl::StatusOr<Principal> who = registry.Authenticate("s1");
  ASSERT_TRUE(who.ok()) << who.status();
  EXPECT_EQ(who->role, Role::kSensor);
  EXPECT_EQ(who->token_id, real.substr(0, 12));
  registry.Add(real, {Role::kViewer});  // same digest: replaced, not added
  EXPECT_EQ(registry.size(), 2u);
  EXPECT_EQ(registry.Authenticate("s1")->role, Role::kViewer);
  EXPECT_EQ(registry.Revoke(real), 1);  // a full digest revokes that entry only
  EXPECT_TRUE(absl::IsUnauthenticated(registry.Authenticate("s1").status()));
  EXPECT_EQ(registry.size(), 1u);
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
  for (Action a : {Action::kSubscribe, Action::kReadModel, Action::kManageCameras, Action::kManageTokens,
                   Action::kManageModels}) {
    EXPECT_TRUE(absl::IsPermissionDenied(Authorize(sensor, a))) << ActionName(a);
  }

  EXPECT_TRUE(Authorize(viewer, Action::kSubscribe).ok());
  EXPECT_TRUE(Authorize(viewer, Action::kReadModel).ok());
  for (Action a : {Action::kStream, Action::kManageCameras, Action::kManageTokens, Action::kManageModels}) {
    const absl::Status s = Authorize(viewer, a, "cam1");
    EXPECT_TRUE(absl::IsPermissionDenied(s)) << ActionName(a);
    EXPECT_THAT(std::string(s.message()), HasSubstr("role viewer"));
  }

  for (Action a : {Action::kSubscribe, Action::kReadModel, Action::kManageCameras, Action::kManageTokens,
                   Action::kManageModels}) {
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
