#pragma once
// A small courtyard for the sensor generators' tests (i4D-like): sloped terrain, a few buildings of
// different primitives, trees, a static object, people walking around a LiDAR at the local zero,
// a car, and a backpack camera walking a path. World origin at UTM-like magnitudes.
#include "model_store/scene/campus.h"

namespace ave::sim::testing {

inline scene::SyntheticCampus CourtyardSite() {
  scene::SyntheticCampus site;
  site.name = "test-courtyard";
  site.origin = Eigen::Vector3d(652431.0, 5287654.0, 112.0);
  site.half_extent_m = 60;
  auto building = [](std::string id, Eigen::Vector2d c, Eigen::Vector2d size, double yaw, double h) {
    scene::BoxBuilding b;
    b.id = std::move(id);
    b.center_m = c;
    b.size_m = size;
    b.yaw_rad = yaw;
    b.height_m = h;
    return b;
  };
  site.buildings = {building("north", {0, 25}, {40, 8}, 0, 9), building("east", {24, 0}, {8, 30}, 0.1, 14),
                    building("west", {-22, -4}, {10, 10}, 0.4, 6)};
  scene::Tree tree;
  tree.position_m = {9, 9};
  site.trees.push_back(tree);
  tree.position_m = {-10, 12};
  tree.crown_radius_m = 3;
  site.trees.push_back(tree);
  scene::StaticObject kiosk;
  kiosk.id = "kiosk";
  kiosk.position_m = {-6, -9};
  kiosk.size_m = {2, 2, 2.5};
  site.objects.push_back(kiosk);
  for (uint32_t i = 0; i < 6; ++i) {
    scene::Mover m;
    m.id = i + 1;
    m.kind = scene::MoverKind::kPerson;
    const double r = 5 + 2.0 * i;
    m.loop_m = {{-r, -r}, {r, -r}, {r, r * 0.5}, {-r, r * 0.5}};
    m.start_offset_m = 7.0 * i;
    m.speed_mps = 1.2 + 0.1 * i;
    site.movers.push_back(m);
  }
  scene::Mover car;
  car.id = 101;
  car.kind = scene::MoverKind::kCar;
  car.loop_m = {{-40, -25}, {40, -25}};
  car.speed_mps = 5;
  car.size_m = {1.8, 4.5, 1.5};
  site.movers.push_back(car);
  scene::CameraSpec backpack;
  backpack.id = "backpack";
  backpack.intrinsics = PinholeIntrinsics::FromFov(640, 480, 70);
  backpack.path = scene::CameraPath{{{-20, -15}, {0, -15}, {10, -5}, {10, 15}}, 1.4, 1.7, 10};
  backpack.world_from_camera = scene::CameraPoseAt(site, backpack, 0);
  site.cameras.push_back(backpack);
  return site;
}

}  // namespace ave::sim::testing
