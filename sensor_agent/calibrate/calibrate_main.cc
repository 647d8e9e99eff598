// ave-calibrate: camera intrinsics and distortion from chessboard images (Zhang's method).
//   ave-calibrate --images 'DIR/*.jpg' --board 9x6 --square 0.025 --out cam.yaml
// COLSxROWS counts inner corners. Prints a one-line JSON summary; exit 1 when the images cannot
// constrain the model (too few views, all views parallel), 2 on a bad flag.
#include <filesystem>
#include <iostream>

#include "model_store/common/cli.h"
#include "sensor_agent/calibrate/calibrate.h"
#include "model_store/scene/intrinsics_file.h"

int main(int argc, char** argv) {
  std::string images, board_text, out;
  double square_m = 0;
  int min_views = 3;
  CLI::App app{"ave-calibrate: camera intrinsics from chessboard images (Zhang's method)"};
  app.add_option("--images", images, "glob of chessboard images, e.g. 'DIR/*.jpg' (quote it)")->required();
  app.add_option("--board", board_text, "inner corners COLSxROWS, e.g. 9x6")->required();
  app.add_option("--square", square_m, "side of one square (metres)")->required()->check(ave::cli::PositiveNumber());
  app.add_option("--out", out, "intrinsics YAML to write (ave-agent / ave-admin --intrinsics)")->required()->check(ave::cli::WritableFile());
  app.add_option("--min-views", min_views, "fewest usable views accepted")->capture_default_str()->check(ave::cli::Range(3, 1000));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-calibrate")) return *exit_code;
  ave::calib::BoardSpec board;
  board.square_m = square_m;
  if (!ave::calib::ParseBoardSize(board_text, board.cols, board.rows)) {
    std::cerr << "ave-calibrate: --board must be COLSxROWS (inner corners), got '" << board_text << "'\n";
    return 2;
  }
  // The result is written last: a missing folder is said before the (slow) calibration.
  if (const std::filesystem::path folder = std::filesystem::path(out).parent_path();
      !folder.empty() && !std::filesystem::is_directory(folder)) {
    std::cerr << "ave-calibrate: --out " << out << ": no folder " << folder.string() << "\n";
    return 2;
  }
  const std::vector<std::string> paths = ave::calib::GlobFiles(images);
  if (paths.empty()) {
    std::cerr << "ave-calibrate: --images '" << images << "' matches no file\n";
    return 1;
  }
  auto result = ave::calib::CalibrateFromImages(paths, board, min_views);
  if (!result.ok()) {
    std::cerr << "ave-calibrate: " << result.status().message() << "\n";
    return 1;
  }
  for (const std::string& why : result->skipped) std::cerr << "ave-calibrate: skipped " << why << "\n";
  if (absl::Status s = ave::calib::WriteIntrinsicsFile(out, result->intrinsics, result->rms_px, result->images_used); !s.ok()) {
    std::cerr << "ave-calibrate: " << s.message() << "\n";
    return 1;
  }
  std::cout << ave::calib::SummaryJson(*result, out) << std::endl;
  return 0;
}
