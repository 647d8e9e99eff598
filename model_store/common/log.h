#pragma once
// Minimal leveled logging to stderr, one line per call, safe from several threads:
//   AVE_LOG(INFO) << "camera '" << id << "': connected";
// Lines carry the UTC time (ms) and the level; nothing is buffered across lines.
#include <chrono>
#include <cstdio>
#include <ctime>
#include <sstream>
#include <string>

namespace ave::log {

enum class Level { kDEBUG = 0, kINFO = 1, kWARNING = 2, kERROR = 3 };

// Messages below this level are dropped; set from --log-level in the executables.
inline Level& MinLevel() {
  static Level level = Level::kINFO;
  return level;
}

class Line {
 public:
  explicit Line(Level level) : level_(level) {}
  ~Line() {
    if (level_ < MinLevel()) return;
    const auto now = std::chrono::system_clock::now();
    const std::time_t secs = std::chrono::system_clock::to_time_t(now);
    const int ms = static_cast<int>(
        std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000);
    std::tm tm{};
    gmtime_r(&secs, &tm);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%H:%M:%S", &tm);
    static const char* kNames[] = {"DEBUG", "INFO", "WARN", "ERROR"};
    const std::string line = std::string(stamp) + "." + (ms < 100 ? (ms < 10 ? "00" : "0") : "") + std::to_string(ms) +
                             " " + kNames[static_cast<int>(level_)] + " " + stream_.str() + "\n";
    std::fputs(line.c_str(), stderr);
  }
  template <typename T>
  Line& operator<<(const T& v) {
    if (level_ >= MinLevel()) stream_ << v;
    return *this;
  }

 private:
  Level level_;
  std::ostringstream stream_;
};

}  // namespace ave::log

#define AVE_LOG(severity) ::ave::log::Line(::ave::log::Level::k##severity)

namespace ave {
// Wall-clock time in nanoseconds since the Unix epoch.
inline int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}
}  // namespace ave
