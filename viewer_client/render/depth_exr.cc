// --depth F.exr: linear depth as a single-channel float OpenEXR image.
#include <exception>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>

#include "viewer_client/render/renderer.h"

namespace ave::viewer {

absl::Status WriteDepthExr(const std::string& path, const std::vector<float>& depth, int width, int height) {
  if (width <= 0 || height <= 0 || depth.size() != static_cast<size_t>(width) * height) {
    return absl::InvalidArgumentError("WriteDepthExr: " + path + ": " + std::to_string(depth.size()) +
                                      " values for " + std::to_string(width) + "x" + std::to_string(height));
  }
  try {
    Imf::Header header(width, height);
    header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file(path.c_str(), header);
    Imf::FrameBuffer frame;
    frame.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(depth.data())), sizeof(float),
                                 sizeof(float) * static_cast<size_t>(width)));
    file.setFrameBuffer(frame);
    file.writePixels(height);
  } catch (const std::exception& e) {
    return absl::InternalError("WriteDepthExr: " + path + ": " + e.what());
  }
  return absl::OkStatus();
}

}  // namespace ave::viewer
