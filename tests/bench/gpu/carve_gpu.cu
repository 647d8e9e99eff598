// What a GPU changes for the studio's visual hull (issue 17, `ave-bench studio`'s "what a GPU would
// change"): the flat voxel carve — every voxel of the capture box projected into every camera, a
// voxel kept when no camera that sees it calls it background and at least 3/4 of the cameras see
// it (model_store/studio/visual_hull.h's rules with tolerance K = 0) — once on one CPU core and
// once on the GPU, on the same frame set, with the kept voxel counts compared.
//
// Not part of the CMake build (CI has no GPU and no CUDA): built with nvcc by hand, run on the
// device machine that some tasks are lent; input from tests/bench/gpu/studio_frameset_raw.py.
//   nvcc -O3 -std=c++17 -o carve_gpu tests/bench/gpu/carve_gpu.cu
//   ./carve_gpu frameset.raw [voxel_mm ...]
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

namespace {

constexpr int kMaxCameras = 32;
struct Box {
  float min[3], size_m;  // voxel size
  int n[3];              // voxels per axis
};
__constant__ double c_P[kMaxCameras * 12];

// One voxel: 1 kept, 0 carved or outside the capture volume. Shared by host and device so the
// two runs are the same arithmetic.
__host__ __device__ inline uint8_t CarveVoxel(const double* P, const uint8_t* const* masks, int cameras, int width,
                                              int height, const Box& box, int ix, int iy, int iz) {
  const double x = box.min[0] + (ix + 0.5) * box.size_m, y = box.min[1] + (iy + 0.5) * box.size_m,
               z = box.min[2] + (iz + 0.5) * box.size_m;
  int seen = 0;
  for (int c = 0; c < cameras; ++c) {
    const double* p = P + 12 * c;
    const double w = p[8] * x + p[9] * y + p[10] * z + p[11];
    if (!(w > 1e-6)) continue;  // behind the camera: no vote
    const double u = (p[0] * x + p[1] * y + p[2] * z + p[3]) / w, v = (p[4] * x + p[5] * y + p[6] * z + p[7]) / w;
    const int px = static_cast<int>(floor(u + 0.5)), py = static_cast<int>(floor(v + 0.5));
    if (px < 0 || py < 0 || px >= width || py >= height) continue;  // outside the image: no vote
    ++seen;
    if (masks[c][static_cast<size_t>(py) * width + px] == 0) return 0;  // background: carved
  }
  return 4 * seen >= 3 * cameras ? 1 : 0;
}

__global__ void CarveKernel(const uint8_t* const* masks, int cameras, int width, int height, Box box, uint8_t* out,
                            unsigned long long* kept) {
  const long long n = static_cast<long long>(box.n[0]) * box.n[1] * box.n[2];
  const long long i = blockIdx.x * static_cast<long long>(blockDim.x) + threadIdx.x;
  uint8_t k = 0;
  if (i < n) {
    const int ix = static_cast<int>(i % box.n[0]), iy = static_cast<int>((i / box.n[0]) % box.n[1]),
              iz = static_cast<int>(i / (static_cast<long long>(box.n[0]) * box.n[1]));
    k = CarveVoxel(c_P, masks, cameras, width, height, box, ix, iy, iz);
    out[i] = k;
  }
  const unsigned ballot = __ballot_sync(0xffffffffu, k);
  if ((threadIdx.x & 31) == 0 && ballot) atomicAdd(kept, static_cast<unsigned long long>(__popc(ballot)));
}

#define CUDA_OK(x)                                                                      \
  do {                                                                                  \
    cudaError_t e = (x);                                                                \
    if (e != cudaSuccess) {                                                             \
      std::fprintf(stderr, "carve_gpu: %s: %s\n", #x, cudaGetErrorString(e));           \
      std::exit(1);                                                                     \
    }                                                                                   \
  } while (0)

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: carve_gpu frameset.raw [voxel_mm ...]\n");
    return 2;
  }
  std::ifstream in(argv[1], std::ios::binary);
  uint32_t header[3];
  if (!in.read(reinterpret_cast<char*>(header), sizeof header)) {
    std::fprintf(stderr, "carve_gpu: %s: no header\n", argv[1]);
    return 1;
  }
  const int cameras = static_cast<int>(header[0]), width = static_cast<int>(header[1]), height = static_cast<int>(header[2]);
  if (cameras < 1 || cameras > kMaxCameras || width < 1 || height < 1 || width > 8192 || height > 8192) {
    std::fprintf(stderr, "carve_gpu: %s: %d cameras of %dx%d is not a frame set\n", argv[1], cameras, width, height);
    return 1;
  }
  std::vector<double> P(12 * cameras);
  std::vector<std::vector<uint8_t>> masks(cameras, std::vector<uint8_t>(static_cast<size_t>(width) * height));
  for (int c = 0; c < cameras; ++c) {
    if (!in.read(reinterpret_cast<char*>(&P[12 * c]), 12 * sizeof(double)) ||
        !in.read(reinterpret_cast<char*>(masks[c].data()), static_cast<std::streamsize>(masks[c].size()))) {
      std::fprintf(stderr, "carve_gpu: %s: truncated at camera %d\n", argv[1], c);
      return 1;
    }
  }
  std::vector<double> voxel_mm;
  for (int a = 2; a < argc; ++a) voxel_mm.push_back(std::atof(argv[a]));
  if (voxel_mm.empty()) voxel_mm = {20, 10, 5};

  cudaDeviceProp prop{};
  CUDA_OK(cudaGetDeviceProperties(&prop, 0));
  std::printf("GPU: %s, %d SMs; frame set: %d cameras of %dx%d; box 3 x 3 x 2.2 m (the studio bench's)\n", prop.name,
              prop.multiProcessorCount, cameras, width, height);

  // Upload: the masks of one frame set (what changes every frame) and the projections.
  std::vector<uint8_t*> d_masks(cameras);
  uint8_t** d_mask_table = nullptr;
  cudaEvent_t e0, e1;
  CUDA_OK(cudaEventCreate(&e0));
  CUDA_OK(cudaEventCreate(&e1));
  for (int c = 0; c < cameras; ++c) CUDA_OK(cudaMalloc(&d_masks[c], masks[c].size()));
  CUDA_OK(cudaMalloc(&d_mask_table, cameras * sizeof(uint8_t*)));
  CUDA_OK(cudaMemcpy(d_mask_table, d_masks.data(), cameras * sizeof(uint8_t*), cudaMemcpyHostToDevice));
  CUDA_OK(cudaMemcpyToSymbol(c_P, P.data(), P.size() * sizeof(double)));
  float upload_ms = 1e9f;
  for (int rep = 0; rep < 5; ++rep) {
    CUDA_OK(cudaEventRecord(e0));
    for (int c = 0; c < cameras; ++c) CUDA_OK(cudaMemcpyAsync(d_masks[c], masks[c].data(), masks[c].size(), cudaMemcpyHostToDevice));
    CUDA_OK(cudaEventRecord(e1));
    CUDA_OK(cudaEventSynchronize(e1));
    float ms = 0;
    CUDA_OK(cudaEventElapsedTime(&ms, e0, e1));
    upload_ms = std::min(upload_ms, ms);
  }
  std::printf("upload of the frame set's masks (pageable memory): %.3f ms\n\n", upload_ms);
  std::printf("| voxel mm | voxels | kept | CPU one core ms | GPU kernel ms (best of 20) | GPU / CPU | same voxels |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- |\n");

  std::vector<const uint8_t*> host_masks(cameras);
  for (int c = 0; c < cameras; ++c) host_masks[c] = masks[c].data();
  for (double mm : voxel_mm) {
    Box box{{-1.5f, -1.5f, 0.0f}, static_cast<float>(mm / 1000.0), {0, 0, 0}};
    box.n[0] = box.n[1] = static_cast<int>(std::lround(3.0 / box.size_m));
    box.n[2] = static_cast<int>(std::lround(2.2 / box.size_m));
    const long long n = static_cast<long long>(box.n[0]) * box.n[1] * box.n[2];
    // CPU: the same function, one thread.
    std::vector<uint8_t> cpu(static_cast<size_t>(n));
    const auto t0 = std::chrono::steady_clock::now();
    unsigned long long cpu_kept = 0;
    for (int iz = 0; iz < box.n[2]; ++iz)
      for (int iy = 0; iy < box.n[1]; ++iy)
        for (int ix = 0; ix < box.n[0]; ++ix) {
          const size_t i = (static_cast<size_t>(iz) * box.n[1] + iy) * box.n[0] + ix;
          cpu[i] = CarveVoxel(P.data(), host_masks.data(), cameras, width, height, box, ix, iy, iz);
          cpu_kept += cpu[i];
        }
    const double cpu_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    // GPU.
    uint8_t* d_out = nullptr;
    unsigned long long* d_kept = nullptr;
    CUDA_OK(cudaMalloc(&d_out, static_cast<size_t>(n)));
    CUDA_OK(cudaMalloc(&d_kept, sizeof(unsigned long long)));
    const int threads = 256;
    const long long blocks = (n + threads - 1) / threads;
    float best = 1e9f;
    unsigned long long gpu_kept = 0;
    for (int rep = 0; rep < 20; ++rep) {
      CUDA_OK(cudaMemset(d_kept, 0, sizeof(unsigned long long)));
      CUDA_OK(cudaEventRecord(e0));
      CarveKernel<<<static_cast<unsigned>(blocks), threads>>>(d_mask_table, cameras, width, height, box, d_out, d_kept);
      CUDA_OK(cudaEventRecord(e1));
      CUDA_OK(cudaEventSynchronize(e1));
      CUDA_OK(cudaGetLastError());
      float ms = 0;
      CUDA_OK(cudaEventElapsedTime(&ms, e0, e1));
      best = std::min(best, ms);
      CUDA_OK(cudaMemcpy(&gpu_kept, d_kept, sizeof gpu_kept, cudaMemcpyDeviceToHost));
    }
    std::vector<uint8_t> gpu(static_cast<size_t>(n));
    CUDA_OK(cudaMemcpy(gpu.data(), d_out, gpu.size(), cudaMemcpyDeviceToHost));
    size_t differ = 0;
    for (size_t i = 0; i < gpu.size(); ++i) differ += gpu[i] != cpu[i];
    std::printf("| %.0f | %lld | %llu | %.1f | %.3f | x%.0f faster | %s |\n", mm, n, gpu_kept, cpu_ms, best, cpu_ms / best,
                differ == 0 && gpu_kept == cpu_kept ? "yes" : ("NO: " + std::to_string(differ) + " differ").c_str());
    CUDA_OK(cudaFree(d_out));
    CUDA_OK(cudaFree(d_kept));
  }
  return 0;
}
