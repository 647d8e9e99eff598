// Data selection end to end (issue 7 item 5): a real FusionServer with 50 cameras streaming over
// gRPC, and SceneClients that send their view frusta. A viewer looking at one block receives the
// frames of only the few cameras that see it (every camera that sees it, by ray-cast truth), poses
// and status of all 50; when its view moves to another block it re-subscribes and gets those.
#include <algorithm>
#include <iostream>
#include <unistd.h>

#include <gtest/gtest.h>

#include "tests/select_site.h"
#include "viewer_client/client/scene_client.h"

namespace ave {
namespace {

using select_site::Site;
using viewer::CameraView;

constexpr int kCameras = 50;

std::set<std::string> WithFrames(const std::vector<CameraView>& cams) {
  std::set<std::string> out;
  for (const auto& c : cams)
    if (c.jpegs_received > 0) out.insert(c.id);
  return out;
}

std::string Join(const std::set<std::string>& ids) {
  std::string s;
  for (const auto& id : ids) s += id + " ";
  return s;
}

TEST(DataSelection, ViewerLookingAtOneBlockReceivesOnlyTheStreamsItSees) {
  auto site = Site::Start("ave_select", kCameras);
  ASSERT_TRUE(site.ok()) << site.status();
  (*site)->StartStreaming(4);

  viewer::SceneClient selecting((*site)->channel(), select_site::kViewer, "selecting");
  absl::StatusOr<TriangleMesh> mesh = selecting.FetchStaticModel();
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  const MeshBvh bvh(*mesh);
  const scene::SyntheticCampus& campus = (*site)->campus();
  // One block in the south-west, then one in the north-east.
  const viewer::View block_a = select_site::BlockView(campus, -60, -55);
  const viewer::View block_b = select_site::BlockView(campus, 55, 60);
  const std::set<std::string> truth_a = select_site::CamerasSeenInView(bvh, (*site)->cameras(), block_a, 600);
  const std::set<std::string> truth_b = select_site::CamerasSeenInView(bvh, (*site)->cameras(), block_b, 600);
  ASSERT_GE(truth_a.size(), 1u);
  ASSERT_GE(truth_b.size(), 1u);

  selecting.SetViews(viewer::SelectionOf({block_a}));
  selecting.Start({.reselect_interval = std::chrono::milliseconds(200)});
  viewer::SceneClient everything((*site)->channel(), select_site::kViewer, "everything");
  everything.Start({});

  auto has = [](const std::set<std::string>& want) {
    return [want](const std::vector<CameraView>& cams) {
      const std::set<std::string> got = WithFrames(cams);
      return cams.size() == size_t(kCameras) && std::includes(got.begin(), got.end(), want.begin(), want.end());
    };
  };
  ASSERT_TRUE(selecting.WaitUntil(has(truth_a), std::chrono::seconds(20)))
      << "expected frames from " << Join(truth_a) << "got " << Join(WithFrames(selecting.Snapshot()));
  std::set<std::string> all_ids;
  for (const auto& cam : (*site)->cameras()) all_ids.insert(cam.id);
  ASSERT_TRUE(everything.WaitUntil(has(all_ids), std::chrono::seconds(20)));
  std::this_thread::sleep_for(std::chrono::seconds(1));  // a few more frames from every camera

  const std::vector<CameraView> a = selecting.Snapshot();
  const std::set<std::string> got_a = WithFrames(a);
  ASSERT_EQ(a.size(), size_t(kCameras));  // poses and status for every camera
  for (const auto& cam : a) EXPECT_NE(cam.status, viewer::CameraLiveness::kUnknown) << cam.id;
  // Every camera that sees the block, and only a few more (the test is conservative).
  EXPECT_TRUE(std::includes(got_a.begin(), got_a.end(), truth_a.begin(), truth_a.end()));
  EXPECT_LE(got_a.size(), truth_a.size() + 4) << "received " << Join(got_a) << "; truth " << Join(truth_a);
  EXPECT_LE(got_a.size(), 10u);
  std::cout << "data selection: block A seen by " << truth_a.size() << " cameras (ray-cast), frames from " << got_a.size()
            << " of " << kCameras << "; " << selecting.jpeg_bytes_received() << " vs " << everything.jpeg_bytes_received()
            << " JPEG bytes\n";
  EXPECT_LT(selecting.jpeg_bytes_received() * 3, everything.jpeg_bytes_received())
      << selecting.jpeg_bytes_received() << " vs " << everything.jpeg_bytes_received() << " bytes";

  // The view moves to the other block: one re-subscription, and that block's cameras arrive.
  const uint64_t subscriptions = selecting.subscriptions();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (selecting.subscriptions() == subscriptions && std::chrono::steady_clock::now() < deadline) {
    selecting.SetViews(viewer::SelectionOf({block_b}));  // called every frame by the viewer
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
  }
  EXPECT_EQ(selecting.subscriptions(), subscriptions + 1);
  std::map<std::string, uint64_t> before;
  for (const auto& cam : selecting.Snapshot()) before[cam.id] = cam.jpegs_received;
  auto new_frames_from = [&](const std::set<std::string>& want) {
    return [&, want](const std::vector<CameraView>& cams) {
      return std::all_of(want.begin(), want.end(), [&](const std::string& id) {
        return std::any_of(cams.begin(), cams.end(), [&](const CameraView& c) { return c.id == id && c.jpegs_received > before[id]; });
      });
    };
  };
  EXPECT_TRUE(selecting.WaitUntil(new_frames_from(truth_b), std::chrono::seconds(20))) << "truth " << Join(truth_b);
  // Cameras of block A alone stop: no new frames for them after a settling second.
  std::this_thread::sleep_for(std::chrono::seconds(1));
  std::map<std::string, uint64_t> settled;
  for (const auto& cam : selecting.Snapshot()) settled[cam.id] = cam.jpegs_received;
  std::this_thread::sleep_for(std::chrono::seconds(1));
  int still_streaming_a_only = 0;
  for (const auto& cam : selecting.Snapshot()) {
    if (truth_a.count(cam.id) && !truth_b.count(cam.id) && cam.jpegs_received > settled[cam.id]) ++still_streaming_a_only;
  }
  EXPECT_EQ(still_streaming_a_only, 0);

  selecting.Stop();
  everything.Stop();
  (*site)->StopStreaming();
  site->reset();
}

TEST(DataSelection, ServerRefusesMalformedViewsByField) {
  auto site = Site::Start("ave_select_bad", 2);
  ASSERT_TRUE(site.ok()) << site.status();
  auto stub = v1::SceneService::NewStub((*site)->channel());
  auto subscribe = [&](const v1::SubscribeRequest& request) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + select_site::kViewer);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    auto reader = stub->Subscribe(&context, request);
    v1::SceneUpdate update;
    if (reader->Read(&update)) context.TryCancel();  // accepted: not what these requests expect
    return reader->Finish();
  };
  v1::SubscribeRequest short_matrix;
  short_matrix.add_views()->add_view_projection(1);
  grpc::Status s = subscribe(short_matrix);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("views[0].view_projection"), std::string::npos) << s.error_message();
  v1::SubscribeRequest singular;
  v1::ViewFrustum* zeros = singular.add_views();
  for (int k = 0; k < 16; ++k) zeros->add_view_projection(0);
  s = subscribe(singular);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("singular"), std::string::npos) << s.error_message();
  site->reset();
}

}  // namespace
}  // namespace ave
