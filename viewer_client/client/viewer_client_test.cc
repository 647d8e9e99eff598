// The viewer application's pure parts: the browse camera (fly and orbit), picking and screen
// projection of annotations, and when a view change is worth a new subscription.
#include <epoxy/gl.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/geometry/camera.h"
#include "viewer_client/client/browse_camera.h"
#include "viewer_client/client/overlay.h"
#include "viewer_client/client/scene_client.h"
#include "viewer_client/client/viewer_app.h"
#include "viewer_client/render/gl_context.h"

namespace ave::viewer {
namespace {

// Where the pivot appears in the browse view, in NDC.
Eigen::Vector2d PivotNdc(const BrowseCamera& cam) {
  const View v = BrowseView({0, 0, 640, 480}, cam.eye(), cam.Target(), 60);
  const Eigen::Vector4d clip = v.projection * v.view * cam.pivot().homogeneous();
  return clip.head<2>() / clip.w();
}

TEST(BrowseCamera, OrbitKeepsThePivotCentredAndItsDistance) {
  BrowseCamera cam({-50, -60, 40}, {10, 5, 0});
  const double r = (cam.eye() - cam.pivot()).norm();
  for (const Eigen::Vector2d& drag : {Eigen::Vector2d(120, 0), Eigen::Vector2d(0, 60), Eigen::Vector2d(-300, -200)}) {
    cam.Apply({.orbit_px = drag});
    EXPECT_NEAR((cam.eye() - cam.pivot()).norm(), r, 1e-9 * r);
    EXPECT_LT(PivotNdc(cam).norm(), 1e-6) << "drag " << drag.transpose();
  }
  EXPECT_NEAR(cam.pivot().x(), 10, 1e-12);
}

TEST(BrowseCamera, OrbitOverTheTopStopsShortOfVertical) {
  BrowseCamera cam({-50, 0, 10}, {0, 0, 0});
  cam.Apply({.orbit_px = Eigen::Vector2d(0, 1e5)});
  const Eigen::Vector3d offset = cam.eye() - cam.pivot();
  EXPECT_GT(offset.z(), 0.99 * offset.norm());
  EXPECT_GT(offset.head<2>().norm(), 1e-3);  // never exactly vertical: LookAt stays defined
  EXPECT_TRUE(cam.WorldFromCamera().translation.allFinite());
  EXPECT_LT(PivotNdc(cam).norm(), 1e-6);
}

TEST(BrowseCamera, FlyMovesAlongTheViewAndDragsThePivot) {
  BrowseCamera cam({0, 0, 10}, {100, 0, 10});
  cam.set_speed(10);
  cam.Apply({.forward = 1, .dt_s = 0.5});
  EXPECT_NEAR(cam.eye().x(), 5, 1e-9);
  EXPECT_NEAR(cam.pivot().x(), 105, 1e-9);
  cam.Apply({.right = 1, .fast = true, .dt_s = 0.5});  // 4x: 20 m to the right of +x = -y
  EXPECT_NEAR(cam.eye().y(), -20, 1e-9);
  cam.Apply({.up = -1, .dt_s = 1});
  EXPECT_NEAR(cam.eye().z(), 0, 1e-9);
}

TEST(BrowseCamera, MouseLookTurnsWithoutMovingAndWheelApproachesThePivot) {
  BrowseCamera cam({0, 0, 10}, {100, 0, 10});
  const Eigen::Vector3d eye = cam.eye();
  cam.Apply({.look_px = Eigen::Vector2d(-M_PI / 2 / BrowseCamera::kRadPerPx, 0)});  // 90 degrees left
  EXPECT_EQ(cam.eye(), eye);
  EXPECT_NEAR(cam.Forward().y(), 1, 1e-9);
  BrowseCamera zoom({0, 0, 10}, {100, 0, 10});
  zoom.Apply({.wheel = 1});
  EXPECT_NEAR(zoom.eye().x(), 10, 1e-9);
  zoom.Apply({.wheel = 1000});  // never through the pivot
  EXPECT_NEAR((zoom.pivot() - zoom.eye()).norm(), 1, 1e-9);
}

// The time line's seek (issue 18): inside a recorded interval of any camera it starts there, in a
// gap at the next recorded instant, near now or after everything recorded it is live.
TEST(PlanSeek, StartsInsideRecordingSkipsGapsAndGoesLiveNearNowOrPastTheRecording) {
  RecordedSpans spans;
  spans.cameras.push_back({"cam1", {{100, 200}, {500, 600}}, 10});
  spans.cameras.push_back({"cam2", {{300, 350}}, 3});
  constexpr int64_t kNow = 1000, kMargin = 50;
  auto seek = [&](int64_t t) { return PlanSeek(t, kNow, spans, kMargin); };
  EXPECT_FALSE(seek(150).live);
  EXPECT_EQ(seek(150).from_ns, 150);  // inside cam1's first interval
  EXPECT_EQ(seek(150).to_ns, kNow);
  EXPECT_EQ(seek(0).from_ns, 100);    // before everything: the first frame
  EXPECT_EQ(seek(250).from_ns, 300);  // cam1's gap: cam2's interval comes first
  EXPECT_EQ(seek(340).from_ns, 340);  // inside cam2's only
  EXPECT_EQ(seek(400).from_ns, 500);  // a gap of both
  EXPECT_EQ(seek(600).from_ns, 600);  // the last instant recorded
  EXPECT_TRUE(seek(700).live);        // after everything recorded
  EXPECT_TRUE(seek(960).live);        // within the margin of now
  EXPECT_TRUE(PlanSeek(150, kNow, {}, kMargin).live);  // nothing recorded
  EXPECT_TRUE(PlanSeek(500, 520, spans, kMargin).live);  // the next recorded instant is too near now
}

TEST(Overlay, ProjectAndPickAndRayAgree) {
  const View view = BrowseView({100, 50, 640, 480}, {0, -80, 60}, {0, 0, 0}, 60);
  const int fb_h = 720;
  const Eigen::Vector3d p(12, 7, 3);
  const auto px = ProjectToScreen(view, fb_h, p);
  ASSERT_TRUE(px);
  EXPECT_GT(px->x(), 100);
  EXPECT_LT(px->x(), 740);
  EXPECT_GT(px->y(), fb_h - 530);
  EXPECT_LT(px->y(), fb_h - 50);
  // The pixel's ray passes through the point.
  const auto [origin, dir] = PixelRayOfView(view, fb_h, *px);
  const Eigen::Vector3d to_p = p - origin;
  EXPECT_LT((to_p - to_p.dot(dir) * dir).norm(), 1e-6 * to_p.norm());
  // Behind the eye or outside the viewport: not drawn.
  EXPECT_FALSE(ProjectToScreen(view, fb_h, {0, -200, 150}));
  EXPECT_FALSE(ProjectToScreen(view, fb_h, {5000, 0, 0}));

  CameraView a, b;
  a.id = "a";
  a.world_from_camera.translation = p;
  b.id = "b";
  b.world_from_camera.translation = {-30, 10, 5};
  EXPECT_EQ(PickCamera(view, fb_h, {a, b}, *px + Eigen::Vector2d(5, -5)), "a");
  EXPECT_EQ(PickCamera(view, fb_h, {a, b}, *px + Eigen::Vector2d(40, 0)), "");
}

// Headless (EGL): the panel and the labels are in the pixels a snapshot reads back.
TEST(Overlay, PanelAndLabelsAppearHeadless) {
  constexpr int kW = 640, kH = 360;
  auto context = CreateHeadlessContext(kW, kH);
  ASSERT_TRUE(context.ok()) << context.status();
  ASSERT_TRUE((*context)->MakeCurrent().ok());
  auto overlay = Overlay::Create();
  ASSERT_TRUE(overlay.ok()) << overlay.status();
  CameraView cam;
  cam.id = "camA";
  cam.status = CameraLiveness::kLive;
  cam.world_from_camera.translation = {0, 0, 0};
  const View view = BrowseView({0, 0, kW, kH}, {0, -60, 40}, {0, 0, 0}, 60);
  const auto label_at = ProjectToScreen(view, kH, cam.world_from_camera.translation);
  ASSERT_TRUE(label_at);
  auto draw = [&](bool panel, bool labels) {
    (*context)->BindFramebuffer();
    glViewport(0, 0, kW, kH);
    glClearColor(0.2f, 0.3f, 0.4f, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    OverlayState state;
    state.panel = panel;
    state.annotations = labels;
    for (int pass = 0; pass < 2; ++pass) {  // the first frame sizes the auto-sized panel
      (*overlay)->BeginFrame(kW, kH, nullptr, 1.0 / 30);
      if (state.panel) (*overlay)->Panel({cam}, {}, 0, state);
      (*overlay)->Annotate(view, kH, {cam}, {}, state);
      if (pass == 0) (*overlay)->DiscardFrame();
    }
    (*overlay)->EndFrame();
    auto pixels = (*context)->ReadPixels();
    EXPECT_TRUE(pixels.ok());
    return *pixels;
  };
  const std::vector<uint8_t> bare = draw(false, false), with = draw(true, true);
  auto differs = [&](int x0, int y0, int x1, int y1) {
    int n = 0;
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x)
        for (int c = 0; c < 3; ++c) n += bare[(size_t(y) * kW + x) * 4 + c] != with[(size_t(y) * kW + x) * 4 + c];
    return n;
  };
  EXPECT_GT(differs(10, 10, 100, 40), 500) << "no panel at the top left";
  const int lx = int(label_at->x()), ly = int(label_at->y());
  EXPECT_GT(differs(lx + 6, ly - 16, lx + 40, ly), 100) << "no label right above the camera marker";
  EXPECT_EQ(differs(kW - 60, kH - 40, kW, kH), 0) << "the overlay drew where nothing belongs";
}

// Issue 18: the panel's time line, drawn headless over the last minute (1 min zoom) of two cameras'
// recordings; a press at three quarters of its width and a release there is a seek to 45 s after
// its left end, at most a pixel's worth of time off (and nothing before the release).
TEST(Overlay, DragOnTheTimeLineSeeksToTheTimeUnderTheCursor) {
  constexpr int kW = 800, kH = 600;
  auto context = CreateHeadlessContext(kW, kH);
  ASSERT_TRUE(context.ok()) << context.status();
  ASSERT_TRUE((*context)->MakeCurrent().ok());
  auto overlay = Overlay::Create();
  ASSERT_TRUE(overlay.ok()) << overlay.status();
  OverlayState state;
  state.open_replay = true;
  state.timeline_zoom = 0;  // 1 min
  state.timeline_now_ns = 100'000'000'000;
  state.recorded.cameras.push_back({"camA", {{50'000'000'000, 70'000'000'000}, {80'000'000'000, 99'000'000'000}}, 100});
  state.recorded.cameras.push_back({"camB", {{45'000'000'000, 99'500'000'000}}, 200});
  auto frame = [&](const WindowInput* input) {
    (*context)->BindFramebuffer();
    (*overlay)->BeginFrame(kW, kH, input, 1.0 / 30);
    (*overlay)->Panel({}, {}, 0, state);
    (*overlay)->EndFrame();
  };
  frame(nullptr);
  frame(nullptr);  // the auto-sized panel has its size
  const auto [x, y, w, h] = state.timeline_rect_px;
  ASSERT_GT(w, 100.f);
  ASSERT_GT(h, 4.f);
  EXPECT_EQ(state.replay_command, OverlayState::ReplayCommand::kNone);
  WindowInput press;
  press.cursor_px = Eigen::Vector2d(x + 0.75 * w, y + h / 2);
  press.left_down = true;
  press.left_presses = 1;
  frame(&press);
  EXPECT_EQ(state.replay_command, OverlayState::ReplayCommand::kNone) << "a seek before the release";
  WindowInput release;
  release.cursor_px = press.cursor_px;
  frame(&release);
  ASSERT_EQ(state.replay_command, OverlayState::ReplayCommand::kSeek);
  const double pixel_ns = 60e9 / w;
  EXPECT_NEAR(static_cast<double>(state.replay_seek_ns), 85e9, 1.5 * pixel_ns);
  // The "live" button is where the panel says it is (what the window test clicks): a click there
  // goes back to live.
  state.replay_command = OverlayState::ReplayCommand::kNone;
  const auto [lx, ly, lw, lh] = state.live_button_rect_px;
  ASSERT_GT(lw, 10.f);
  ASSERT_GT(ly, y + h) << "the live button is below the time line";
  WindowInput click;
  click.cursor_px = Eigen::Vector2d(lx + lw / 2, ly + lh / 2);
  click.left_down = true;
  click.left_presses = 1;
  frame(&click);
  click.left_down = false;
  click.left_presses = 0;
  frame(&click);
  EXPECT_EQ(state.replay_command, OverlayState::ReplayCommand::kLive);
}

// Issue 7 performance: the overlay is redrawn into its cache only when its triangles changed, and
// then at once on input or moving views, otherwise at most at content_refresh_hz; a cached frame
// composites the same pixels.
TEST(Overlay, CacheRedrawsOnInputMovingViewsAndDueContentChangesOnly) {
  constexpr int kW = 480, kH = 320;
  auto context = CreateHeadlessContext(kW, kH);
  ASSERT_TRUE(context.ok()) << context.status();
  ASSERT_TRUE((*context)->MakeCurrent().ok());
  EXPECT_FALSE(Overlay::Create({.content_refresh_hz = -1}).ok());
  auto overlay = Overlay::Create({.content_refresh_hz = 1e-3});  // content alone never redraws here
  ASSERT_TRUE(overlay.ok()) << overlay.status();
  CameraView cam;
  cam.id = "camA";
  cam.status = CameraLiveness::kLive;
  OverlayState state;
  auto draw = [&](double fps, const WindowInput* input, bool views_moved) {
    (*context)->BindFramebuffer();
    glViewport(0, 0, kW, kH);
    glClearColor(0.2f, 0.3f, 0.4f, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    (*overlay)->BeginFrame(kW, kH, input, 1.0 / 30);
    (*overlay)->Panel({cam}, {.fps = fps}, 0, state);
    (*overlay)->EndFrame(views_moved);
    return *(*context)->ReadPixels();
  };
  draw(10, nullptr, false);  // auto-sizing frame
  const uint64_t first = (*overlay)->redraws();
  EXPECT_GE(first, 1u);
  const std::vector<uint8_t> drawn = draw(10, nullptr, false);
  const uint64_t after_same = (*overlay)->redraws();
  const std::vector<uint8_t> cached = draw(10, nullptr, false);
  EXPECT_EQ((*overlay)->redraws(), after_same) << "unchanged content was redrawn";
  EXPECT_EQ(cached, drawn) << "the cached overlay composites other pixels than it drew";
  draw(25, nullptr, false);
  EXPECT_EQ((*overlay)->redraws(), after_same) << "a content change redrew before content_refresh_hz allowed";
  draw(26, nullptr, true);
  EXPECT_EQ((*overlay)->redraws(), after_same + 1) << "moving views did not redraw";
  WindowInput input;
  input.cursor_px = {300, 200};
  draw(27, &input, false);
  EXPECT_EQ((*overlay)->redraws(), after_same + 2) << "input did not redraw";
  draw(27, &input, false);  // same cursor, same content
  EXPECT_EQ((*overlay)->redraws(), after_same + 2);
  auto every_change = Overlay::Create();  // default: every change redraws
  ASSERT_TRUE(every_change.ok());
  for (double fps : {10.0, 11.0, 11.0}) {
    (*every_change)->BeginFrame(kW, kH, nullptr, 1.0 / 30);
    (*every_change)->Panel({cam}, {.fps = fps}, 0, state);
    (*every_change)->EndFrame();
  }
  EXPECT_EQ((*every_change)->redraws(), 2u);
}

TEST(JpegDecode, ReducesOnlyWhileTheLayerSizeIsKept) {
  EXPECT_EQ(JpegReduction(640, 480, 640, 480), 1);
  EXPECT_EQ(JpegReduction(1279, 960, 640, 480), 1);
  EXPECT_EQ(JpegReduction(1280, 960, 640, 480), 2);
  EXPECT_EQ(JpegReduction(1920, 1080, 640, 480), 2);
  EXPECT_EQ(JpegReduction(2560, 1920, 640, 480), 4);
  EXPECT_EQ(JpegReduction(20000, 15000, 640, 480), 8);
  EXPECT_EQ(JpegReduction(1280, 960, 0, 0), 1);
  EXPECT_EQ(JpegReduction(0, 0, 640, 480), 1);
}

TEST(JpegDecode, DecodesRgbaAtTheReducedSizeAndRefusesGarbage) {
  cv::Mat bgr(96, 128, CV_8UC3, cv::Scalar(30, 60, 220));  // BGR: red dominant
  std::vector<uint8_t> bytes;
  ASSERT_TRUE(cv::imencode(".jpg", bgr, bytes));
  const std::string jpeg(bytes.begin(), bytes.end());
  for (int reduction : {1, 2, 4}) {
    const auto image = DecodeJpeg(jpeg, reduction);
    ASSERT_NE(image, nullptr);
    EXPECT_EQ(image->width, 128 / reduction);
    EXPECT_EQ(image->height, 96 / reduction);
    ASSERT_EQ(image->rgba.size(), size_t(image->width) * image->height * 4);
    EXPECT_NEAR(image->rgba[0], 220, 6);
    EXPECT_NEAR(image->rgba[1], 60, 6);
    EXPECT_NEAR(image->rgba[2], 30, 6);
    EXPECT_EQ(image->rgba[3], 255);
  }
  EXPECT_EQ(DecodeJpeg("not a jpeg"), nullptr);
  EXPECT_EQ(DecodeJpeg(""), nullptr);
  // The reasons the viewer logs (issue 14: the checked decoder of model_store/image).
  EXPECT_EQ(DecodeJpegFrame("not a jpeg").status().message(), "not a JPEG or PNG image (first bytes 6e 6f 74 20)");
  std::vector<uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", bgr, png));
  EXPECT_EQ(DecodeJpegFrame(std::string(png.begin(), png.end())).status().message(), "a camera frame must be a JPEG, not a PNG");
  EXPECT_NE(DecodeJpegFrame(jpeg.substr(0, 40)).status().message().find("truncated JPEG"), std::string::npos);
}

TEST(DataSelection, SmallMovesKeepTheSubscriptionLargeOnesRenewIt) {
  auto views = [](const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int n) {
    std::vector<View> out(n, BrowseView({0, 0, 640, 480}, eye, target, 60));
    return SelectionOf(out);
  };
  const SelectionViews base = views({0, -80, 60}, {0, 0, 0}, 1);
  EXPECT_FALSE(ViewsDifferALot(base, base));
  EXPECT_FALSE(ViewsDifferALot(base, views({0.5, -80, 60}, {0.5, 0, 0}, 1)));
  EXPECT_TRUE(ViewsDifferALot(base, views({0, -80, 60}, {60, 0, 0}, 1)));  // turned
  EXPECT_TRUE(ViewsDifferALot(base, views({80, -80, 60}, {80, 0, 0}, 1)));  // moved a block
  EXPECT_TRUE(ViewsDifferALot(base, views({0, -80, 60}, {0, 0, 0}, 2)));   // a view added
  EXPECT_TRUE(ViewsDifferALot(base, SelectionViews{}));                   // selection switched off
}

TEST(LidarPointLayer, EveryLidarsPointsColouredByTrackGreyWhenUnassigned) {
  auto cloud = std::make_shared<LidarPointCloud>();
  cloud->p_local = {{1, 2, 0.5f}, {1.1f, 2, 1.0f}, {5, 5, 1}};
  cloud->track_id = {7, 7, 0};
  auto other = std::make_shared<LidarPointCloud>();
  other->p_local = {{-3, 4, 1.5f}};
  other->track_id = {9};
  std::vector<LidarView> lidars(3);
  lidars[0].points = cloud;
  lidars[1].points = nullptr;  // a LiDAR whose points have not arrived
  lidars[2].points = other;
  const PointCloud drawn = LidarPointsByTrack(lidars);
  ASSERT_EQ(drawn.positions_local_m.size(), 4u);
  ASSERT_EQ(drawn.colors.size(), 4u);
  EXPECT_EQ(drawn.positions_local_m[1], Eigen::Vector3f(1.1f, 2, 1.0f));
  EXPECT_EQ(drawn.positions_local_m[3], Eigen::Vector3f(-3, 4, 1.5f));
  EXPECT_EQ(drawn.colors[0], IdColor(7));
  EXPECT_EQ(drawn.colors[1], drawn.colors[0]) << "one person, one colour";
  EXPECT_EQ(drawn.colors[2], IdColor(0));
  EXPECT_EQ(drawn.colors[3], IdColor(9));
  EXPECT_NE(drawn.colors[3], drawn.colors[0]);
  EXPECT_TRUE(LidarPointsByTrack({}).positions_local_m.empty());
}

// A viewer that opened while only some cameras had reported (CI stop 40: the third cell stayed a
// plan view that moved with the browse view) fills its cells as the cameras come.
TEST(LockedViews, EmptyCellsTakeTheNextCamerasByIdAsTheyReport) {
  using Cells = std::array<std::string, 3>;
  Cells cells = FillLockedViews({}, {});
  EXPECT_EQ(cells, Cells({"", "", ""}));
  cells = FillLockedViews(cells, {"cam1", "cam3"});
  EXPECT_EQ(cells, Cells({"cam1", "cam3", ""})) << "two cameras so far: the third cell waits";
  // A camera earlier by id reports later: the filled cells keep theirs (no view jumps under the
  // operator), the empty one takes it.
  cells = FillLockedViews(cells, {"backpack", "cam1", "cam2", "cam3"});
  EXPECT_EQ(cells, Cells({"cam1", "cam3", "backpack"}));
  EXPECT_EQ(FillLockedViews(cells, {"backpack", "cam1", "cam2", "cam3", "cam4"}), cells) << "full cells stay";
  // An operator who emptied the middle cell: the next camera not shown elsewhere goes in.
  EXPECT_EQ(FillLockedViews({"cam2", "", "backpack"}, {"backpack", "cam1", "cam2"}), Cells({"cam2", "cam1", "backpack"}));
  EXPECT_EQ(FillLockedViews({"", "", ""}, {"a", "b", "c", "d"}), Cells({"a", "b", "c"}));
}

TEST(ViewerOptions, CheckNamesTheProblem) {
  ViewerOptions o;
  EXPECT_EQ(o.Check(), "");
  o.headless = true;
  EXPECT_NE(o.Check().find("--snapshot"), std::string::npos);
  o.record_dir = "/tmp/x";
  EXPECT_EQ(o.Check(), "");
  o.servers = {};
  EXPECT_NE(o.Check().find("server"), std::string::npos);
  // Issue 14: the viewer token goes in plaintext to loopback only, unless told.
  o.servers = {"127.0.0.1:50051", "10.0.0.7:50051"};
  EXPECT_NE(o.Check().find("'10.0.0.7:50051'"), std::string::npos);
  EXPECT_NE(o.Check().find("--insecure-plaintext"), std::string::npos);
  o.insecure_plaintext = true;
  EXPECT_EQ(o.Check(), "");
  o.insecure_plaintext = false;
  o.tls_ca = "ca.pem";
  EXPECT_EQ(o.Check(), "");
}

}  // namespace
}  // namespace ave::viewer
