// ave-admin: manage the camera registry of a running ave-server.
//   ave-admin list
//   ave-admin add-camera --id cam9 --name "Gate" --size 1280x720 --fov 70 --position 10,20,15 --look-at 30,40,0
//   ave-admin update-camera ... (same flags; every field is replaced)
//   ave-admin add-lidar --id hdl64 --position -2,-3,2.1 [--quaternion w,x,y,z | --yaw-deg 0]
//   ave-admin update-lidar ... (same flags)
//   ave-admin remove-camera --id cam9  (LiDARs too)
//   ave-admin import-campus [--moving] (registers the built-in campus cameras, skipping existing ones;
//                                       --moving: also the scenario's moving cameras, e.g. the backpack)
//   ave-admin issue-token --role sensor --camera cam1   (prints the new token once)
//   ave-admin revoke-token --id 3f2a9c01b7e4 | list-tokens
//   ave-admin export --camera cam1 --from T --to T2 --out clip.mkv   (recorded frames, issue 18)
//   ave-admin put-avatar --file walk.avseq [--name walk] | list-avatars   (issue 17)
// TLS: --tls-ca ca.pem (and --tls-cert/--tls-key for mutual TLS); env AVE_TLS_CA.
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <sstream>

#include <google/protobuf/util/json_util.h>
#include <nlohmann/json.hpp>

#include "ave/net/tls.h"
#include "fusion_server/admin/admin_client.h"
#include "fusion_server/admin/export.h"
#include "fusion_server/core/convert.h"
#include "model_store/avatar/avatar_blob.h"
#include "model_store/common/cli.h"
#include "model_store/scene/intrinsics_file.h"

namespace {

int Fail(const std::string& what) {
  std::cerr << "ave-admin: " << what << "\n";
  return 1;
}

// Protobuf messages (cameras, token records) as one pretty JSON array on stdout.
template <typename Messages>
int PrintJsonArray(const Messages& messages) {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& m : messages) {
    std::string json;
    (void)google::protobuf::util::MessageToJsonString(m, &json);
    out.push_back(nlohmann::json::parse(json));
  }
  std::cout << out.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string server = "127.0.0.1:50051";
  const char* env_token = std::getenv("AVE_ADMIN_TOKEN");
  std::string token = env_token ? env_token : "";
  CLI::App app{"ave-admin: manage the cameras of an AVE fusion server"};
  app.add_option("--server", server, "server host:port")->capture_default_str();
  app.add_option("--token", token, "admin bearer token (env AVE_ADMIN_TOKEN)");
  ave::net::TlsClientOptions tls;
  if (const char* ca = std::getenv("AVE_TLS_CA")) tls.ca_file = ca;
  app.add_option("--tls-ca", tls.ca_file, "PEM CA of the server certificate: use TLS (env AVE_TLS_CA)");
  app.add_option("--tls-cert", tls.cert_file, "PEM client certificate (mutual TLS)");
  app.add_option("--tls-key", tls.key_file, "PEM client key (mutual TLS)");
  app.add_option("--tls-server-name", tls.server_name, "name the server certificate carries, if not the host dialled");
  app.add_flag("--insecure-plaintext", tls.insecure_plaintext,
               "send the admin token in plaintext to a non-loopback server (without --tls-ca)");
  app.require_subcommand(1);
  CLI::App* export_clip = app.add_subcommand("export", "write a camera's recorded frames between two times as a Motion-JPEG clip");
  std::string export_camera, export_out;
  double export_from_s = 0, export_to_s = 0;
  export_clip->add_option("--camera", export_camera, "camera id")->required();
  export_clip->add_option("--from", export_from_s, "start: server time in seconds since the Unix epoch, or <= 0 for seconds before now")
      ->required();
  export_clip->add_option("--to", export_to_s, "end, the same forms (0 = now)")->required();
  export_clip->add_option("--out", export_out, "output clip, .mkv or .avi")->required();

  app.add_subcommand("list", "list registered cameras as JSON");
  std::string id, name, source, size = "640x480", position, look_at, quaternion;
  double fov_deg = 60;
  std::string intrinsics_file;
  bool disabled = false;
  auto add_camera_flags = [&](CLI::App* sub) {
    sub->add_option("--id", id, "camera id ([A-Za-z0-9_.-], 1..64)")->required();
    sub->add_option("--name", name, "display name");
    sub->add_option("--size", size, "image size WIDTHxHEIGHT")->capture_default_str();
    sub->add_option("--fov", fov_deg, "horizontal field of view, degrees")->capture_default_str()->check(ave::cli::Range(1.0, 179.0));
    sub->add_option("--intrinsics", intrinsics_file, "intrinsics YAML from ave-calibrate (replaces --size and --fov)");
    sub->add_option("--position", position, "camera centre x,y,z in the site's local frame (m)")->required();
    sub->add_option("--look-at", look_at, "point x,y,z the camera looks at");
    sub->add_option("--quaternion", quaternion, "world_from_camera rotation w,x,y,z (instead of --look-at)");
    sub->add_option("--source", source, "source URL (rtsp://..., file:..., sim:campus#id)");
    sub->add_flag("--disabled", disabled, "register disabled");
  };
  CLI::App* add = app.add_subcommand("add-camera", "register a camera");
  add_camera_flags(add);
  CLI::App* update = app.add_subcommand("update-camera", "replace a camera's record");
  add_camera_flags(update);
  // Rotating LiDARs (issue 16): registered like cameras, with a kind and no intrinsics. The
  // rotation is world_from_sensor (default identity: sensor axes along east, north, up).
  double yaw_deg = 0;
  auto add_lidar_flags = [&](CLI::App* sub) {
    sub->add_option("--id", id, "sensor id ([A-Za-z0-9_.-], 1..64)")->required();
    sub->add_option("--name", name, "display name");
    sub->add_option("--position", position, "sensor origin x,y,z in the site's local frame (m)")->required();
    sub->add_option("--quaternion", quaternion, "world_from_sensor rotation w,x,y,z");
    sub->add_option("--yaw-deg", yaw_deg, "or a rotation about the vertical, degrees counter-clockwise from east");
    sub->add_option("--source", source, "source (pcap:..., udp:..., sim:courtyard#hdl64)");
    sub->add_flag("--disabled", disabled, "register disabled");
  };
  CLI::App* add_lidar = app.add_subcommand("add-lidar", "register a fixed rotating LiDAR");
  add_lidar_flags(add_lidar);
  CLI::App* update_lidar = app.add_subcommand("update-lidar", "replace a rotating LiDAR's record");
  add_lidar_flags(update_lidar);
  CLI::App* remove = app.add_subcommand("remove-camera", "remove a camera or LiDAR");
  remove->add_option("--id", id, "camera id")->required();
  CLI::App* import_campus = app.add_subcommand("import-campus", "register the built-in campus cameras (existing ids are skipped)");
  bool import_moving = false;
  import_campus->add_flag("--moving", import_moving,
                          "also the campus scenario's moving cameras (the backpack walker; its agent streams a pose per frame)");
  std::string role, label, token_id;
  CLI::App* issue = app.add_subcommand("issue-token", "issue a bearer token; prints it once (the server keeps its hash)");
  issue->add_option("--role", role, "sensor, viewer or admin")->required()->check(CLI::IsMember({"sensor", "viewer", "admin"}));
  issue->add_option("--camera", id, "the camera a sensor token may stream as");
  issue->add_option("--label", label, "free text naming the holder");
  CLI::App* revoke = app.add_subcommand("revoke-token", "revoke tokens by id (a prefix of the hash, 8+ hex)");
  revoke->add_option("--id", token_id, "token id as issue-token / list-tokens print it")->required();
  app.add_subcommand("list-tokens", "list issued tokens (ids, roles, cameras; never the tokens) as JSON");
  std::string avatar_file;
  CLI::App* put_avatar = app.add_subcommand("put-avatar", "store an avatar sequence (.avseq from the studio)");
  put_avatar->add_option("--file", avatar_file, "the .avseq file")->required();
  put_avatar->add_option("--name", name, "name to store it under ([A-Za-z0-9_.-]{1,64}; default: the file's own)");
  app.add_subcommand("list-avatars", "list stored avatar sequences (no blobs) as JSON");

  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-admin")) return *exit_code;
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = ave::net::MakeChannel(server, tls);
  if (!channel.ok()) return Fail(std::string(channel.status().message()));
  ave::AdminClient client(*channel, token);

  if (app.got_subcommand("export")) {
    const double now_s = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
    auto absolute_ns = [&](double s) { return static_cast<int64_t>((s <= 0 ? now_s + s : s) * 1e9); };
    auto done = ave::ExportClip(*channel, token, {export_camera, absolute_ns(export_from_s), absolute_ns(export_to_s), export_out});
    if (!done.ok()) return Fail(std::string(done.status().message()));
    std::cout << "exported " << done->frames << " frames of " << export_camera << " (" << done->width << "x"
              << done->height << ", " << done->fps << " fps) to " << export_out
              << (done->gaps ? " (" + std::to_string(done->gaps) + " recorded frames unreadable)" : "") << "\n";
    return 0;
  }
  if (app.got_subcommand("issue-token")) {
    auto issued = client.IssueToken(role, id, label);
    if (!issued.ok()) return Fail(std::string(issued.status().message()));
    std::cerr << "issued " << issued->info().role() << " token " << issued->info().token_id()
              << (issued->info().camera_id().empty() ? "" : " for camera " + issued->info().camera_id())
              << " (shown once)\n";
    std::cout << issued->token() << "\n";
    return 0;
  }
  if (app.got_subcommand("revoke-token")) {
    if (absl::Status s = client.RevokeToken(token_id); !s.ok()) return Fail(std::string(s.message()));
    std::cout << "revoked " << token_id << "\n";
    return 0;
  }
  if (app.got_subcommand("list-tokens")) {
    auto tokens = client.ListTokens();
    if (!tokens.ok()) return Fail(std::string(tokens.status().message()));
    return PrintJsonArray(*tokens);
  }

  if (app.got_subcommand("put-avatar")) {
    // Read and checked here first, so a bad file is named by its path before anything is sent.
    absl::StatusOr<ave::avatar::AvatarSequence> sequence = ave::avatar::ReadAvatarSequenceFile(avatar_file);
    if (!sequence.ok()) return Fail(std::string(sequence.status().message()));
    absl::StatusOr<std::string> blob = ave::avatar::EncodeAvatarSequence(*sequence, avatar_file);
    if (!blob.ok()) return Fail(std::string(blob.status().message()));
    auto info = client.PutAvatarSequence(*blob, name);
    if (!info.ok()) return Fail(std::string(info.status().message()));
    std::cout << "stored avatar sequence '" << info->name() << "' version " << info->version() << " ("
              << info->frame_count() << " frames, " << info->bytes() << " bytes)\n";
    return 0;
  }
  if (app.got_subcommand("list-avatars")) {
    auto sequences = client.ListAvatarSequences();
    if (!sequences.ok()) return Fail(std::string(sequences.status().message()));
    return PrintJsonArray(*sequences);
  }
  if (app.got_subcommand("list")) {
    auto cameras = client.ListCameras();
    if (!cameras.ok()) return Fail(std::string(cameras.status().message()));
    return PrintJsonArray(*cameras);
  }
  if (app.got_subcommand("remove-camera")) {
    if (absl::Status s = client.RemoveCamera(id); !s.ok()) return Fail(std::string(s.message()));
    std::cout << "removed " << id << "\n";
    return 0;
  }
  if (app.got_subcommand("import-campus")) {
    auto existing = client.ListCameras();
    if (!existing.ok()) return Fail(std::string(existing.status().message()));
    int added = 0;
    std::vector<ave::scene::CameraSpec> specs = ave::scene::BuiltinCampus().cameras;
    if (import_moving) {
      for (const auto& spec : ave::scene::BuiltinCampusMovingCameras()) specs.push_back(spec);
    }
    for (const auto& spec : specs) {
      bool present = false;
      for (const auto& c : *existing) present |= c.id() == spec.id;
      if (present) continue;
      auto r = client.AddCamera(ave::CampusCameraRecord(spec));
      if (!r.ok()) return Fail(std::string(r.status().message()));
      ++added;
    }
    std::cout << "campus cameras: " << added << " added, " << existing->size() << " already registered\n";
    return 0;
  }
  if (app.got_subcommand("add-lidar") || app.got_subcommand("update-lidar")) {
    Eigen::Vector3d origin;
    if (!ave::cli::ParseVec3(position, origin)) return Fail("--position must be x,y,z, got '" + position + "'");
    ave::Rigid3d world_from_sensor;
    world_from_sensor.translation = origin;
    if (!quaternion.empty()) {
      std::stringstream qs(quaternion);
      double w, qx, qy, qz;
      char c1, c2, c3;
      if (!(qs >> w >> c1 >> qx >> c2 >> qy >> c3 >> qz)) return Fail("--quaternion must be w,x,y,z");
      world_from_sensor.rotation = Eigen::Quaterniond(w, qx, qy, qz);  // the server checks it is unit
    } else {
      world_from_sensor.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitZ()));
    }
    ave::v1::Camera lidar = ave::LidarRecord(id, name, world_from_sensor, source);
    lidar.set_enabled(!disabled);
    const bool adding = app.got_subcommand("add-lidar");
    auto result = adding ? client.AddCamera(lidar) : client.UpdateCamera(lidar);
    if (!result.ok()) return Fail(std::string(result.status().message()));
    std::cout << (adding ? "added lidar " : "updated lidar ") << id << "\n";
    return 0;
  }
  // add-camera / update-camera
  int width = 0, height = 0;
  char x = 0;
  std::stringstream ss(size);
  if (!(ss >> width >> x >> height) || x != 'x') return Fail("--size must be WIDTHxHEIGHT, got '" + size + "'");
  Eigen::Vector3d eye, target;
  if (!ave::cli::ParseVec3(position, eye)) return Fail("--position must be x,y,z, got '" + position + "'");
  ave::Rigid3d pose;
  if (!look_at.empty()) {
    if (!ave::cli::ParseVec3(look_at, target)) return Fail("--look-at must be x,y,z, got '" + look_at + "'");
    pose = ave::LookAt(eye, target);
  } else if (!quaternion.empty()) {
    std::stringstream qs(quaternion);
    double w, qx, qy, qz;
    char c1, c2, c3;
    if (!(qs >> w >> c1 >> qx >> c2 >> qy >> c3 >> qz)) return Fail("--quaternion must be w,x,y,z");
    pose.rotation = Eigen::Quaterniond(w, qx, qy, qz);  // sent as given: the server checks it is unit
    pose.translation = eye;
  } else {
    return Fail("give --look-at or --quaternion");
  }
  ave::v1::Camera camera;
  camera.set_id(id);
  camera.set_name(name.empty() ? id : name);
  *camera.mutable_intrinsics() = ave::ToProto(ave::PinholeIntrinsics::FromFov(width, height, fov_deg));
  if (!intrinsics_file.empty()) {
    auto intrinsics = ave::calib::ReadIntrinsicsFile(intrinsics_file);
    if (!intrinsics.ok()) return Fail("--intrinsics: " + std::string(intrinsics.status().message()));
    *camera.mutable_intrinsics() = ave::ToProto(*intrinsics);
  }
  *camera.mutable_mounting_pose() = ave::ToProto(pose);
  camera.set_source_url(source);
  camera.set_enabled(!disabled);
  auto result = app.got_subcommand("add-camera") ? client.AddCamera(camera) : client.UpdateCamera(camera);
  if (!result.ok()) return Fail(std::string(result.status().message()));
  std::cout << (app.got_subcommand("add-camera") ? "added " : "updated ") << id << "\n";
  return 0;
}
