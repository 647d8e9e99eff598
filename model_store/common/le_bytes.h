#pragma once
// Little-endian encoding of fixed-size numbers into byte strings, and a bounds-checked reader:
// the one implementation behind the store's binary blobs (mesh_blob, avatar_blob). Every Get fails
// (returns false, reads nothing) once the input is exhausted, so a truncated blob never reads past
// its end.
#include <bit>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace ave::bytes {

template <typename U>
void PutLe(std::string& out, U v) {
  for (size_t i = 0; i < sizeof(U); ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
inline void PutF32(std::string& out, float f) { PutLe(out, std::bit_cast<uint32_t>(f)); }
inline void PutF64(std::string& out, double d) { PutLe(out, std::bit_cast<uint64_t>(d)); }

class LeReader {
 public:
  explicit LeReader(std::string_view b) : b_(b) {}
  template <typename U>
  bool Get(U& v) {
    if (b_.size() - pos_ < sizeof(U)) return false;
    v = 0;
    for (size_t i = 0; i < sizeof(U); ++i) v |= static_cast<U>(static_cast<uint8_t>(b_[pos_ + i])) << (8 * i);
    pos_ += sizeof(U);
    return true;
  }
  bool GetF32(float& f) {
    uint32_t u;
    if (!Get(u)) return false;
    f = std::bit_cast<float>(u);
    return true;
  }
  bool GetF64(double& d) {
    uint64_t u;
    if (!Get(u)) return false;
    d = std::bit_cast<double>(u);
    return true;
  }
  // The next n bytes, or false when fewer are left.
  bool GetBytes(size_t n, std::string_view& out) {
    if (remaining() < n) return false;
    out = b_.substr(pos_, n);
    pos_ += n;
    return true;
  }
  size_t remaining() const { return b_.size() - pos_; }
  size_t offset() const { return pos_; }

 private:
  std::string_view b_;
  size_t pos_ = 0;
};

}  // namespace ave::bytes
