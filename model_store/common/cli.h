#pragma once
// Shared command-line conventions of the ave-* executables (only their mains include this):
// --help exits 0, a bad flag exits 2 with one line naming it, and "x,y,z" triples parse strictly.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>
#include <Eigen/Core>

namespace ave::cli {

// Parses argv; returns an exit code when the program should stop now (help shown: 0, error: 2).
inline std::optional<int> Parse(CLI::App& app, int argc, char** argv, const std::string& program) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::cerr << program << ": " << e.what() << " (see --help)\n";
    return 2;
  }
  return std::nullopt;
}

// CLI::Range and CLI::PositiveNumber let "nan" through (every comparison with NaN is false): a
// NaN --duration crashed ave-loadgen and a NaN --fps made ave-sim write NaN times (issue 14).
// These take a finite number within [min, max] only; integers flags still parse as integers.
inline CLI::Validator Range(double min, double max) {
  std::ostringstream desc;
  desc << "in [" << min << ", " << max << "]";
  return CLI::Validator(
      [min, max](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (end == text.c_str() || *end != '\0' || !std::isfinite(v) || v < min || v > max) {
          std::ostringstream why;
          why << "value " << text << " is not a finite number in [" << min << ", " << max << "]";
          return why.str();
        }
        return {};
      },
      desc.str(), "FINITE_RANGE");
}
inline CLI::Validator PositiveNumber() { return Range(std::numeric_limits<double>::min(), std::numeric_limits<double>::max()); }

// A file the program will write (a plot, a PNG, a YAML, a model): empty (none) and "-" (stdout)
// pass; otherwise its folder must exist and take a new file, probed by creating and removing one
// (so root on a read-only mount or /proc is refused too), and an existing file must open for
// writing. Checked at parse time, so an unwritable output stops the program before minutes of work
// instead of being lost silently at the end (issue 14, "Input surfaces").
inline CLI::Validator WritableFile() {
  return CLI::Validator(
      [](std::string& path) -> std::string {
        if (path.empty() || path == "-") return {};
        const std::filesystem::path p(path);
        std::filesystem::path dir = p.parent_path();
        if (dir.empty()) dir = ".";
        std::error_code ec;
        if (!std::filesystem::is_directory(dir, ec)) return path + ": no folder " + dir.string();
        if (std::filesystem::is_directory(p, ec)) return path + ": is a folder, not a file";
        const std::string probe = (dir / (".ave-write-probe-" + std::to_string(::getpid()))).string();
        const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
        if (fd < 0) return path + ": folder " + dir.string() + " cannot be written (" + std::strerror(errno) + ")";
        ::close(fd);
        ::unlink(probe.c_str());
        if (std::filesystem::exists(p, ec)) {
          const int existing = ::open(path.c_str(), O_WRONLY);
          if (existing < 0) return path + ": cannot be written (" + std::strerror(errno) + ")";
          ::close(existing);
        }
        return {};
      },
      "FILE (writable)", "WRITABLE_FILE");
}

// "x,y,z" (metres, site frame) -> a vector; false on any other shape.
inline bool ParseVec3(const std::string& text, Eigen::Vector3d& out) {
  std::stringstream ss(text);
  char c1 = 0, c2 = 0;
  double x, y, z;
  if (!(ss >> x >> c1 >> y >> c2 >> z) || c1 != ',' || c2 != ',' || !(ss >> std::ws).eof()) return false;
  out = {x, y, z};
  return true;
}

}  // namespace ave::cli
