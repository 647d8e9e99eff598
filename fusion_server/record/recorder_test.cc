#include "fusion_server/record/recorder.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "fusion_server/record/record_index.h"
#include "fusion_server/record/record_test_util.h"

namespace ave::record {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using testing::TempRecording;
using testing::TestFrame;
using testing::TestJpeg;

constexpr int64_t kT0 = 1'700'000'000'000'000'000;  // server clock, ns
constexpr int64_t kFrameNs = 66'666'667;            // 15 fps

int64_t SegmentBytesOnDisk(const std::string& dir) {
  int64_t total = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator(); ++it) {
    if (it->is_regular_file() && it->path().extension() == ".seg") total += static_cast<int64_t>(it->file_size());
  }
  return total;
}

// Every indexed frame: its bytes are there and decode as a JPEG of the declared size.
void ExpectIndexMatchesSegments(const std::string& store_path, const std::string& dir, int width, int height) {
  auto index = RecordIndex::Open(store_path);
  ASSERT_TRUE(index.ok()) << index.status();
  auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 1 << 20);
  ASSERT_TRUE(rows.ok()) << rows.status();
  for (const FrameRow& row : *rows) {
    auto bytes = ReadSegmentBytes(dir, row.segment_path, row.offset, row.length);
    ASSERT_TRUE(bytes.ok()) << bytes.status();
    const cv::Mat image = cv::imdecode(cv::Mat(1, static_cast<int>(bytes->size()), CV_8U, bytes->data()), cv::IMREAD_COLOR);
    ASSERT_FALSE(image.empty()) << row.sensor_id << " #" << row.sequence << " does not decode";
    EXPECT_EQ(image.cols, width);
    EXPECT_EQ(image.rows, height);
  }
  EXPECT_EQ(*(*index)->IntegrityCheck(), "ok");
}

// Whether the filesystem of `dir` takes O_DIRECT (tmpfs before Linux 6.6 does not; the recorder
// then writes through the page cache).
bool DirectIoSupported(const std::string& dir) {
  const fs::path probe = fs::path(dir) / "direct_probe";
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_DIRECT, 0644);
  if (fd >= 0) ::close(fd);
  fs::remove(probe);
  return fd >= 0;
}

RecorderOptions Options(const TempRecording& rec) {
  RecorderOptions o;
  o.dir = rec.dir();
  o.flush_period = std::chrono::milliseconds(50);
  return o;
}

// The time line's intervals: one sensor's segments that touch or lie within the gap merge, a longer
// break (a restart, a deleted stretch) stays a gap; the filter and empty segments.
TEST(MergeSegmentIntervals, MergesCloseSegmentsPerSensorAndKeepsLongerBreaks) {
  auto seg = [](std::string id, int64_t start, int64_t end) {
    SegmentRow row;
    row.sensor_id = std::move(id);
    row.start_ns = start;
    row.end_ns = end;
    return row;
  };
  const std::vector<SegmentRow> segments = {seg("b", 100, 200), seg("a", 50, 60),  seg("a", 0, 40),
                                            seg("a", 45, 55),   seg("a", 90, 95), seg("c", 10, 5)};
  const std::vector<RecordedIntervals> merged = MergeSegmentIntervals(segments, {}, 5);
  ASSERT_EQ(merged.size(), 2u);  // "c" holds only an empty segment
  EXPECT_EQ(merged[0].sensor_id, "a");
  using I = std::pair<int64_t, int64_t>;
  EXPECT_EQ(merged[0].intervals, (std::vector<I>{{0, 60}, {90, 95}}));  // 40..45 merges, 60..90 is a gap
  EXPECT_EQ(merged[1].sensor_id, "b");
  EXPECT_EQ(merged[1].intervals, (std::vector<I>{{100, 200}}));
  const std::vector<RecordedIntervals> only_b = MergeSegmentIntervals(segments, {"b"}, 5);
  ASSERT_EQ(only_b.size(), 1u);
  EXPECT_EQ(only_b[0].sensor_id, "b");
  EXPECT_EQ(MergeSegmentIntervals(segments, {}, 30)[0].intervals.size(), 1u);  // 60..90 is within 30
}

// The index's metadata is written field by field from the received frame (no copy): the same
// bytes as serializing a copy of those fields, for frames with and without pose, boxes, offset.
TEST(FrameMetaBytes, SameBytesAsSerializingACopyWithoutTheJpeg) {
  auto full = TestFrame(7, 123456789, TestJpeg(1));
  full->set_clock_offset_ns(-42);
  v1::DetectedBox* box = full->add_boxes();
  box->set_track_id(9);
  box->set_score(0.5f);
  for (int i = 0; i < 4; ++i) box->add_corners()->set_x(10.0 * i);
  v1::SensorFrame bare;
  bare.set_jpeg("x");
  v1::SensorFrame pose_only;
  pose_only.set_sequence(3);
  pose_only.mutable_pose()->mutable_orientation()->set_w(1);
  for (const v1::SensorFrame* frame : std::vector<const v1::SensorFrame*>{full.get(), &bare, &pose_only}) {
    v1::SensorFrame copy = *frame;
    copy.clear_jpeg();
    const std::string expected = copy.SerializeAsString();
    const std::string bytes = FrameMetaBytes(*frame);
    EXPECT_EQ(bytes, expected);
    v1::SensorFrame parsed;
    ASSERT_TRUE(parsed.ParseFromString(bytes));
    EXPECT_EQ(parsed.boxes_size(), frame->boxes_size());
    EXPECT_EQ(parsed.clock_offset_ns(), frame->clock_offset_ns());
    EXPECT_TRUE(parsed.jpeg().empty());
  }
}

TEST(Recorder, BytesExactlyAsReceivedIndexedInServerCaptureOrder) {
  TempRecording rec;
  std::map<std::pair<std::string, uint64_t>, std::string> sent;
  {
    auto recorder = Recorder::Open(rec.store_path(), Options(rec));
    ASSERT_TRUE(recorder.ok()) << recorder.status();
    // Three cameras; cam-b's sensor clock runs 5 s behind (its offset puts it back on the server clock),
    // and its frames are submitted late: the index orders by the server capture clock, not arrival.
    for (uint64_t k = 1; k <= 20; ++k) {
      for (const std::string id : {"cam-a", "cam-b", "cam-c"}) {
        const int64_t capture_server_ns = kT0 + static_cast<int64_t>(k) * kFrameNs + (id == "cam-b" ? -1000 : 0);
        std::string jpeg = TestJpeg(static_cast<int>(k) + (id == "cam-c" ? 100 : 0));
        auto frame = TestFrame(k, capture_server_ns - (id == "cam-b" ? 5'000'000'000 : 0), jpeg);
        sent[{id, k}] = jpeg;
        (*recorder)->SubmitFrame(id, frame, capture_server_ns + 2'000'000, capture_server_ns);
      }
    }
    (*recorder)->Drain();
    const RecorderStats stats = (*recorder)->Stats();
    EXPECT_EQ(stats.frames_recorded, 60u);
    EXPECT_EQ(stats.queue_drops, 0u);
    std::string metrics;
    (*recorder)->RenderPrometheus(metrics);
    EXPECT_THAT(metrics, HasSubstr("ave_record_frames_total 60\n"));
    EXPECT_THAT(metrics, HasSubstr("ave_record_disk_full 0\n"));
  }
  auto index = RecordIndex::Open(rec.store_path());
  ASSERT_TRUE(index.ok());
  auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 1000);
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 60u);
  for (size_t i = 1; i < rows->size(); ++i) {
    EXPECT_LE((*rows)[i - 1].capture_server_ns, (*rows)[i].capture_server_ns);
  }
  EXPECT_EQ((*rows)[0].sensor_id, "cam-b");  // 1 us earlier on the server clock
  for (const FrameRow& row : *rows) {
    auto bytes = ReadSegmentBytes(rec.dir(), row.segment_path, row.offset, row.length);
    ASSERT_TRUE(bytes.ok()) << bytes.status();
    EXPECT_EQ(*bytes, (sent[{row.sensor_id, row.sequence}])) << row.sensor_id << " #" << row.sequence;
    v1::SensorFrame meta;
    ASSERT_TRUE(meta.ParseFromString(row.meta));
    EXPECT_TRUE(meta.jpeg().empty());
    EXPECT_EQ(meta.pose().position().x(), static_cast<double>(row.sequence));
    EXPECT_EQ(meta.pose().covariance_size(), 36);
    EXPECT_EQ(meta.boxes_size(), 1);
  }
  ExpectIndexMatchesSegments(rec.store_path(), rec.dir(), 160, 120);
}

TEST(Recorder, RollsSegmentsBySizeAndDuration) {
  TempRecording rec;
  RecorderOptions o = Options(rec);
  o.segment_max_bytes = 4 * TestJpeg(0).size();  // about 4 frames each
  o.segment_max_duration = std::chrono::seconds(1);
  {
    auto recorder = Recorder::Open(rec.store_path(), o);
    ASSERT_TRUE(recorder.ok()) << recorder.status();
    for (int k = 0; k < 12; ++k) (*recorder)->SubmitFrame("cam", TestFrame(k + 1, 0, TestJpeg(k)), kT0, kT0 + k * kFrameNs);
    // A long pause: the next frame starts a new segment by duration.
    (*recorder)->SubmitFrame("cam", TestFrame(13, 0, TestJpeg(0)), kT0, kT0 + 5'000'000'000);
    (*recorder)->Drain();
  }
  auto index = RecordIndex::Open(rec.store_path());
  auto segments = (*index)->Segments();
  ASSERT_TRUE(segments.ok());
  EXPECT_GE(segments->size(), 4u);
  EXPECT_EQ(segments->back().start_ns, kT0 + 5'000'000'000);
  int64_t indexed = 0;
  for (const SegmentRow& seg : *segments) {
    EXPECT_TRUE(seg.closed);
    EXPECT_EQ(static_cast<int64_t>(fs::file_size(fs::path(rec.dir()) / seg.path)), seg.bytes) << seg.path;
    indexed += seg.bytes;
  }
  EXPECT_EQ(indexed, SegmentBytesOnDisk(rec.dir()));
}

TEST(Recorder, RetentionByAgeDeletesOldestSegmentsAndTheirRows) {
  TempRecording rec;
  int64_t now_ns = kT0;
  RecorderOptions o = Options(rec);
  o.max_age = std::chrono::seconds(60);
  o.segment_max_duration = std::chrono::seconds(10);
  o.clock_ns = [&] { return now_ns; };
  auto recorder = Recorder::Open(rec.store_path(), o);
  ASSERT_TRUE(recorder.ok());
  for (int k = 0; k < 10; ++k) {  // one frame every 20 s: ten segments over 200 s
    now_ns = kT0 + k * 20'000'000'000;
    (*recorder)->SubmitFrame("cam", TestFrame(k + 1, 0, TestJpeg(k)), now_ns, now_ns);
    (*recorder)->Drain();
  }
  now_ns = kT0 + 200'000'000'000;
  (*recorder)->Drain();
  auto index = RecordIndex::Open(rec.store_path());
  auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 100);
  ASSERT_TRUE(rows.ok());
  // Kept: frames newer than 60 s before now (140 s, 160 s, 180 s).
  ASSERT_EQ(rows->size(), 3u);
  EXPECT_EQ(rows->front().capture_server_ns, kT0 + 140'000'000'000);
  EXPECT_EQ((*recorder)->Stats().segments_deleted, 7u);
  int files = 0;
  for (auto it = fs::recursive_directory_iterator(rec.dir()); it != fs::recursive_directory_iterator(); ++it) {
    files += it->path().extension() == ".seg";
  }
  EXPECT_EQ(files, 3);
  EXPECT_EQ(*(*index)->IntegrityCheck(), "ok");
}

TEST(Recorder, BudgetFullStopsCleanlyThenResumes) {
  TempRecording rec;
  const int64_t frame_bytes = static_cast<int64_t>(TestJpeg(0).size());
  RecorderOptions o = Options(rec);
  o.max_bytes = 3 * frame_bytes + frame_bytes / 2;   // three frames fit
  o.segment_max_bytes = 8 * frame_bytes;             // and all three are in the open segment
  auto recorder = Recorder::Open(rec.store_path(), o);
  ASSERT_TRUE(recorder.ok());
  auto submit = [&](int k) {
    (*recorder)->SubmitFrame("cam", TestFrame(k, 0, TestJpeg(0)), kT0 + k * kFrameNs, kT0 + k * kFrameNs);
    (*recorder)->Drain();
  };
  for (int k = 1; k <= 3; ++k) submit(k);
  EXPECT_FALSE((*recorder)->Stats().disk_full);
  submit(4);  // over budget with nothing closed to delete: stops, skips it
  RecorderStats stats = (*recorder)->Stats();
  EXPECT_EQ(stats.disk_full_events, 1u);
  EXPECT_EQ(stats.disk_full_skips, 1u);
  EXPECT_EQ(stats.frames_recorded, 3u);
  EXPECT_LE(SegmentBytesOnDisk(rec.dir()), o.max_bytes);
  std::string metrics;
  (*recorder)->RenderPrometheus(metrics);
  EXPECT_THAT(metrics, HasSubstr("ave_record_disk_full_events_total 1\n"));
  // Retention deleted the closed segment at the flush: the next frame records again.
  submit(5);
  stats = (*recorder)->Stats();
  EXPECT_FALSE(stats.disk_full);
  EXPECT_EQ(stats.frames_recorded, 4u);
  EXPECT_LE(SegmentBytesOnDisk(rec.dir()), o.max_bytes);
  auto index = RecordIndex::Open(rec.store_path());
  auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 100);
  ASSERT_EQ(rows->size(), 1u);
  EXPECT_EQ(rows->front().sequence, 5u);
  ExpectIndexMatchesSegments(rec.store_path(), rec.dir(), 160, 120);
}

// A write that fails with EFBIG (the process's file size limit: a full disk as write(2) reports
// it, without a small filesystem to mount) stops recording cleanly; it resumes once writes fit.
TEST(Recorder, WriteFailureFromFullDiskStopsAndResumes) {
  TempRecording rec;
  RecorderOptions o = Options(rec);
  const std::string big(400 << 10, 'j');  // segment bytes need not be JPEG for the recorder
  rlimit old_limit{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  signal(SIGXFSZ, SIG_IGN);
  auto recorder = Recorder::Open(rec.store_path(), o);
  ASSERT_TRUE(recorder.ok());
  auto submit = [&](int k) {
    (*recorder)->SubmitFrame("cam", TestFrame(k, 0, big), kT0 + k * kFrameNs, kT0 + k * kFrameNs);
    (*recorder)->Drain();
  };
  submit(1);
  submit(2);
  rlimit limit = old_limit;
  limit.rlim_cur = 1000 << 10;  // room for two frames in the segment
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
  submit(3);
  submit(4);
  RecorderStats stats = (*recorder)->Stats();
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &old_limit), 0);
  EXPECT_TRUE(stats.disk_full);
  EXPECT_EQ(stats.disk_full_events, 1u);
  EXPECT_EQ(stats.disk_full_skips, 2u);
  EXPECT_EQ(stats.frames_recorded, 2u);
  submit(5);
  stats = (*recorder)->Stats();
  EXPECT_FALSE(stats.disk_full);
  EXPECT_EQ(stats.frames_recorded, 3u);
  auto index = RecordIndex::Open(rec.store_path());
  auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 100);
  ASSERT_EQ(rows->size(), 3u);
  EXPECT_EQ(rows->back().sequence, 5u);
  for (const FrameRow& row : *rows) {
    auto bytes = ReadSegmentBytes(rec.dir(), row.segment_path, row.offset, row.length);
    ASSERT_TRUE(bytes.ok()) << bytes.status();
    EXPECT_EQ(*bytes, big);
  }
  EXPECT_EQ(*(*index)->IntegrityCheck(), "ok");
}

// Frames queued together are written by one pwritev per segment; when it fails part-way (the
// file size limit cuts it), every frame of the failed write is cut back and counted as skipped,
// none is indexed, and the segment on disk is exactly as long as its indexed frames.
// Also with --record-direct-io: the O_DIRECT write cut by the limit is undone the same way, and
// the probing frame (buffered) is followed by a direct write that reads back the partial block.
TEST(Recorder, BatchedWriteFailingPartWayDropsEachOfItsFrames) {
  for (const bool direct : {false, true}) {
    SCOPED_TRACE(direct ? "direct io" : "page cache");
    TempRecording rec;
    RecorderOptions o = Options(rec);
    o.direct_io = direct;
    // Not a multiple of 4 KB, and no period that divides one: a block read back from the wrong place shows.
    std::string big((400 << 10) + 1000, 'j');
    for (size_t i = 0; i < big.size(); ++i) big[i] = static_cast<char>('a' + i % 251 % 26);
    rlimit old_limit{};
    ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
    signal(SIGXFSZ, SIG_IGN);
    auto recorder = Recorder::Open(rec.store_path(), o);
    ASSERT_TRUE(recorder.ok());
    auto submit = [&](int k) { (*recorder)->SubmitFrame("cam", TestFrame(k, 0, big), kT0 + k * kFrameNs, kT0 + k * kFrameNs); };
    submit(1);
    submit(2);
    (*recorder)->Drain();
    rlimit limit = old_limit;
    limit.rlim_cur = 1000 << 10;  // the next write gets 200 KB in, then EFBIG
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
    for (int k = 3; k <= 5; ++k) submit(k);  // usually one batch; split, the later ones are skipped or probe and fail
    (*recorder)->Drain();
    RecorderStats stats = (*recorder)->Stats();
    const int64_t on_disk = SegmentBytesOnDisk(rec.dir());
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &old_limit), 0);
    EXPECT_TRUE(stats.disk_full);
    EXPECT_EQ(stats.disk_full_events, 1u);
    EXPECT_EQ(stats.disk_full_skips, 3u);
    EXPECT_EQ(stats.frames_recorded, 2u);
    EXPECT_EQ(on_disk, 2 * static_cast<int64_t>(big.size()));  // the partial write was cut back
    submit(6);  // the probe: written at once, through the page cache
    (*recorder)->Drain();
    submit(7);  // batched again (direct: the block frame 6 ends in is read back and written again)
    (*recorder)->Drain();
    stats = (*recorder)->Stats();
    EXPECT_FALSE(stats.disk_full);
    EXPECT_EQ(stats.frames_recorded, 4u);
    // Frames 1-2 and frame 7 (the cut write is not counted; frame 6 was the buffered probe).
    if (direct && DirectIoSupported(rec.dir())) {
      EXPECT_EQ(stats.direct_writes, 2u);
    }
    auto index = RecordIndex::Open(rec.store_path());
    auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 100);
    ASSERT_EQ(rows->size(), 4u);
    EXPECT_EQ(rows->back().sequence, 7u);
    int64_t indexed = 0;
    for (const FrameRow& row : *rows) {
      indexed += row.length;
      auto bytes = ReadSegmentBytes(rec.dir(), row.segment_path, row.offset, row.length);
      ASSERT_TRUE(bytes.ok()) << bytes.status();
      EXPECT_EQ(*bytes, big);
    }
    (*recorder).reset();  // closes the segment: its reserved tail is released, the size stays
    EXPECT_EQ(SegmentBytesOnDisk(rec.dir()), indexed);
    EXPECT_EQ(*(*index)->IntegrityCheck(), "ok");
  }
}

TEST(Recorder, RestartTruncatesUnindexedTailsAndRemovesUnindexedSegments) {
  TempRecording rec;
  std::string segment;
  {
    auto recorder = Recorder::Open(rec.store_path(), Options(rec));
    ASSERT_TRUE(recorder.ok());
    for (int k = 1; k <= 5; ++k) (*recorder)->SubmitFrame("cam", TestFrame(k, 0, TestJpeg(k)), kT0, kT0 + k * kFrameNs);
    (*recorder)->Drain();
  }
  auto index = RecordIndex::Open(rec.store_path());
  auto segments = (*index)->Segments();
  ASSERT_EQ(segments->size(), 1u);
  const fs::path path = fs::path(rec.dir()) / segments->front().path;
  const int64_t indexed = segments->front().bytes;
  // What a crash between write and commit leaves: bytes past the last indexed one, and a segment
  // file that no row names.
  { std::ofstream(path, std::ios::app | std::ios::binary) << std::string(1000, 'x'); }
  const fs::path orphan = fs::path(rec.dir()) / "cam" / "999.seg";
  { std::ofstream(orphan, std::ios::binary) << TestJpeg(9); }
  ASSERT_EQ(static_cast<int64_t>(fs::file_size(path)), indexed + 1000);
  {
    auto recorder = Recorder::Open(rec.store_path(), Options(rec));
    ASSERT_TRUE(recorder.ok()) << recorder.status();
    EXPECT_EQ(static_cast<int64_t>(fs::file_size(path)), indexed);
    EXPECT_FALSE(fs::exists(orphan));
    // Recording goes on in a new segment; the old one is closed.
    (*recorder)->SubmitFrame("cam", TestFrame(6, 0, TestJpeg(6)), kT0, kT0 + 6 * kFrameNs);
    (*recorder)->Drain();
  }
  segments = (*index)->Segments();
  ASSERT_EQ(segments->size(), 2u);
  EXPECT_TRUE(segments->front().closed);
  ExpectIndexMatchesSegments(rec.store_path(), rec.dir(), 160, 120);
}

TEST(Recorder, FullQueueDropsAndCounts) {
  TempRecording rec;
  RecorderOptions o = Options(rec);
  o.queue_max_items = 1;
  o.flush_period = std::chrono::milliseconds(60'000);
  auto recorder = Recorder::Open(rec.store_path(), o);
  ASSERT_TRUE(recorder.ok());
  // 200 submits as fast as possible into a one-slot queue: each is either recorded or counted as
  // dropped, never lost silently (how many drop depends on the scheduler, so only the sum is fixed).
  const std::string jpeg = TestJpeg(0);
  for (int k = 1; k <= 200; ++k) (*recorder)->SubmitFrame("cam", TestFrame(k, 0, jpeg), kT0, kT0 + k);
  (*recorder)->Drain();
  const RecorderStats stats = (*recorder)->Stats();
  EXPECT_EQ(stats.frames_recorded + stats.queue_drops, 200u);
}

// Three cameras' new bytes in one flush: one syncfs of the recording's filesystem (the default)
// instead of one fdatasync per segment; the index still matches the files either way.
TEST(Recorder, OneSyncfsPerFlushForAllSegmentsOrOneFdatasyncEach) {
  for (const auto method : {RecorderOptions::SyncMethod::kFilesystem, RecorderOptions::SyncMethod::kPerFile}) {
    TempRecording rec;
    RecorderOptions o = Options(rec);
    o.flush_period = std::chrono::milliseconds(60'000);  // flushes only at Drain: one batch
    o.sync_method = method;
    auto recorder = Recorder::Open(rec.store_path(), o);
    ASSERT_TRUE(recorder.ok()) << recorder.status();
    for (int k = 1; k <= 6; ++k) {
      (*recorder)->SubmitFrame("cam" + std::to_string(k % 3), TestFrame(k, 0, TestJpeg(k)), kT0 + k * kFrameNs,
                               kT0 + k * kFrameNs);
    }
    (*recorder)->Drain();
    const RecorderStats stats = (*recorder)->Stats();
    EXPECT_EQ(stats.frames_recorded, 6u);
    EXPECT_EQ(stats.syncs, method == RecorderOptions::SyncMethod::kFilesystem ? 1u : 3u);
    std::string metrics;
    (*recorder)->RenderPrometheus(metrics);
    EXPECT_THAT(metrics, HasSubstr("ave_record_syncs_total " + std::to_string(stats.syncs)));
    recorder->reset();
    ExpectIndexMatchesSegments(rec.store_path(), rec.dir(), 160, 120);
  }
}

// --record-direct-io: batches written with O_DIRECT from an aligned buffer, the partial block at
// a segment's end written again with the next batch. Every frame reads back byte for byte, across
// batches that end mid-block; the block's zeros past the last frame are cut when the segment
// closes; a restart after a segment was left open (a crash) cuts them too.
TEST(Recorder, DirectIoWritesEveryFrameExactlyAcrossBatchesAndCutsThePadding) {
  TempRecording rec;
  const bool direct_supported = DirectIoSupported(rec.dir());
  RecorderOptions o = Options(rec);
  o.direct_io = true;
  o.flush_period = std::chrono::milliseconds(60'000);  // batches end at each Drain
  std::map<std::pair<std::string, uint64_t>, std::string> sent;
  std::map<std::string, int64_t> indexed_end;
  {
    auto recorder = Recorder::Open(rec.store_path(), o);
    ASSERT_TRUE(recorder.ok()) << recorder.status();
    uint64_t k = 0;
    for (int batch = 0; batch < 4; ++batch) {
      for (int i = 0; i < 3 + batch; ++i) {
        ++k;
        for (const std::string id : {"cam-a", "cam-b"}) {
          std::string jpeg = TestJpeg(static_cast<int>(k) * 7 + (id == "cam-b" ? 3 : 0));
          sent[{id, k}] = jpeg;
          const int64_t t = kT0 + static_cast<int64_t>(k) * kFrameNs;
          (*recorder)->SubmitFrame(id, TestFrame(k, t, jpeg), t, t);
        }
      }
      (*recorder)->Drain();
    }
    const RecorderStats stats = (*recorder)->Stats();
    EXPECT_EQ(stats.frames_recorded, 2 * k);
    EXPECT_EQ(stats.write_errors, 0u);
    if (direct_supported) {
      EXPECT_EQ(stats.direct_writes, 8u);  // one per segment per batch
      std::string metrics;
      (*recorder)->RenderPrometheus(metrics);
      EXPECT_THAT(metrics, HasSubstr("ave_record_direct_writes_total 8\n"));
    }
    auto index = RecordIndex::Open(rec.store_path());
    auto segments = (*index)->Segments();
    ASSERT_EQ(segments->size(), 2u);
    for (const SegmentRow& seg : *segments) {
      const int64_t size = static_cast<int64_t>(fs::file_size(fs::path(rec.dir()) / seg.path));
      EXPECT_GE(size, seg.bytes);  // the last block's zeros, while the segment is open
      if (direct_supported) {
        EXPECT_EQ(size % 4096, 0) << seg.path;
      }
      indexed_end[seg.path] = seg.bytes;
    }
    // Read back while still recording (the page cache holds none of these bytes).
    auto rows = (*index)->Frames({}, 0, std::numeric_limits<int64_t>::max(), 1000);
    ASSERT_EQ(rows->size(), 2 * k);
    for (const FrameRow& row : *rows) {
      auto bytes = ReadSegmentBytes(rec.dir(), row.segment_path, row.offset, row.length);
      ASSERT_TRUE(bytes.ok()) << bytes.status();
      EXPECT_EQ(*bytes, (sent[{row.sensor_id, row.sequence}])) << row.sensor_id << " #" << row.sequence;
    }
  }
  for (const auto& [path, bytes] : indexed_end) {
    EXPECT_EQ(static_cast<int64_t>(fs::file_size(fs::path(rec.dir()) / path)), bytes) << path;
  }
  ExpectIndexMatchesSegments(rec.store_path(), rec.dir(), 160, 120);
  // A crash leaves the zeros of a segment's last block past its indexed end: the restart cuts them.
  const fs::path some = fs::path(rec.dir()) / indexed_end.begin()->first;
  { std::ofstream(some, std::ios::app | std::ios::binary) << std::string(4096 - indexed_end.begin()->second % 4096, '\0'); }
  {
    auto recorder = Recorder::Open(rec.store_path(), o);
    ASSERT_TRUE(recorder.ok()) << recorder.status();
    EXPECT_EQ(static_cast<int64_t>(fs::file_size(some)), indexed_end.begin()->second);
  }
}

// The sync period (--record-sync-ms) is when frames become durable and acknowledged as recorded:
// with a minute's period nothing is committed until a drain (or the period) comes.
TEST(Recorder, SyncPeriodDecidesWhenFramesAreCommitted) {
  TempRecording rec;
  RecorderOptions o = Options(rec);
  o.flush_period = std::chrono::milliseconds(60'000);
  auto recorder = Recorder::Open(rec.store_path(), o);
  ASSERT_TRUE(recorder.ok());
  for (int k = 1; k <= 3; ++k) (*recorder)->SubmitFrame("cam", TestFrame(k, 0, TestJpeg(k)), kT0 + k, kT0 + k);
  std::this_thread::sleep_for(std::chrono::milliseconds(600));  // > the default period (500 ms)
  EXPECT_EQ((*recorder)->Stats().commits, 0u);
  EXPECT_EQ((*recorder)->RecordedSequence("cam", 0), 0u);
  (*recorder)->Drain();
  EXPECT_EQ((*recorder)->Stats().commits, 1u);
  EXPECT_EQ((*recorder)->RecordedSequence("cam", 0), 3u);
  o.flush_period = std::chrono::milliseconds(0);
  EXPECT_THAT(o.Check(), HasSubstr("--record-sync-ms"));
  o.flush_period = std::chrono::milliseconds(60'001);
  EXPECT_THAT(o.Check(), HasSubstr("--record-sync-ms"));
}

TEST(Recorder, OptionsCheckNamesTheField) {
  RecorderOptions o;
  EXPECT_THAT(o.Check(), HasSubstr("record dir"));
  o.dir = "/tmp/x";
  o.max_bytes = -1;
  EXPECT_THAT(o.Check(), HasSubstr("max bytes"));
  TempRecording rec;
  auto bad = Recorder::Open(rec.store_path(), o);
  EXPECT_THAT(bad.status().message(), HasSubstr("max bytes"));
}

}  // namespace
}  // namespace ave::record
