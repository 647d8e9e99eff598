#include "sensor_agent/stream/metadata_buffer.h"

#include <cstdio>

namespace ave {

MetadataBuffer::MetadataBuffer(MetadataBufferOptions options) : options_(std::move(options)) {}

MetadataBuffer::~MetadataBuffer() {
  out_.close();
  in_.close();
  if (!options_.spill_path.empty()) std::remove(options_.spill_path.c_str());
}

void MetadataBuffer::Push(v1::SensorFrame frame) {
  frame.clear_jpeg();
  frame.set_metadata_only(true);
  // Records go to memory only while nothing is spilled, so memory always holds the oldest ones.
  if (spilled_ == read_ && memory_.size() < options_.max_in_memory) {
    memory_.push_back(std::move(frame));
    return;
  }
  if (options_.spill_path.empty() || spilled_ - read_ >= options_.max_spilled) {
    ++dropped_;
    return;
  }
  if (!out_.is_open()) {
    out_.open(options_.spill_path, std::ios::binary | std::ios::trunc);
    in_.open(options_.spill_path, std::ios::binary);
    if (!out_ || !in_) {
      ++dropped_;
      out_.close();
      return;
    }
  }
  const std::string bytes = frame.SerializeAsString();
  const uint32_t n = static_cast<uint32_t>(bytes.size());
  out_.write(reinterpret_cast<const char*>(&n), sizeof n);
  out_.write(bytes.data(), n);
  out_.flush();
  if (!out_) {
    ++dropped_;
    return;
  }
  ++spilled_;
}

absl::StatusOr<std::optional<v1::SensorFrame>> MetadataBuffer::Pop() {
  if (unpopped_) {
    std::optional<v1::SensorFrame> f = std::move(unpopped_);
    unpopped_.reset();
    return f;
  }
  if (!memory_.empty()) {
    v1::SensorFrame f = std::move(memory_.front());
    memory_.pop_front();
    return std::optional<v1::SensorFrame>(std::move(f));
  }
  if (read_ == spilled_) {
    if (out_.is_open()) {  // drained: start the next outage with an empty file
      out_.close();
      in_.close();
      std::remove(options_.spill_path.c_str());
      spilled_ = read_ = 0;
    }
    return std::optional<v1::SensorFrame>();
  }
  uint32_t n = 0;
  in_.read(reinterpret_cast<char*>(&n), sizeof n);
  std::string bytes(in_ && n <= (1u << 20) ? n : 0, '\0');  // bound before allocating: n comes from the file
  if (in_ && n <= (1u << 20)) in_.read(bytes.data(), n);
  v1::SensorFrame f;
  if (!in_ || n > (1u << 20) || !f.ParseFromString(bytes)) {
    const size_t lost = spilled_ - read_;
    dropped_ += lost;
    read_ = spilled_;
    return absl::DataLossError("metadata spill file '" + options_.spill_path + "': corrupt record; " +
                               std::to_string(lost) + " records lost");
  }
  ++read_;
  return std::optional<v1::SensorFrame>(std::move(f));
}

void MetadataBuffer::Unpop(v1::SensorFrame frame) { unpopped_ = std::move(frame); }

}  // namespace ave
