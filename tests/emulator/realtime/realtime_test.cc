// Real-time mode (emulator/realtime) and the bench report (emulator/bench): SPSC ring under two
// threads, deadline arithmetic, the pacer with a recording sink, the paper-002 device set, the
// report's key set and statistics. No timing assertions.

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/prctl.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <random>
#include <thread>
#include <vector>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/bench/bench_report.h"
#include "emulator/bench/bench_runner.h"
#include "emulator/bench/paper002_device_set.h"
#include "emulator/realtime/realtime_pacer.h"
#include "emulator/realtime/spsc_ring.h"

namespace wheelhil::emulator {
namespace {

using realtime::PacedFrame;
using realtime::SendRecord;
using realtime::SpscRing;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

TEST(SpscRing, CapacityRoundsUpToPowerOfTwo) {
  EXPECT_EQ(SpscRing<int>(1).capacity(), 2u);
  EXPECT_EQ(SpscRing<int>(5).capacity(), 8u);
  EXPECT_EQ(SpscRing<int>(8).capacity(), 8u);
  EXPECT_THROW(SpscRing<int>(0), std::invalid_argument);
}

TEST(SpscRing, FullAndEmptyOnOneThread) {
  SpscRing<int> ring(4);
  int v = -1;
  EXPECT_FALSE(ring.TryPop(v));
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(ring.TryPush(i));
  EXPECT_FALSE(ring.TryPush(99));
  EXPECT_EQ(ring.SizeApprox(), 4u);
  for (int i = 0; i < 4; ++i) {
    ASSERT_TRUE(ring.TryPop(v));
    EXPECT_EQ(v, i);
  }
  EXPECT_FALSE(ring.TryPop(v));
  EXPECT_EQ(v, 3);  // untouched by a failed pop
  // Wraps around many times.
  for (int i = 0; i < 1000; ++i) {
    ASSERT_TRUE(ring.TryPush(i));
    ASSERT_TRUE(ring.TryPop(v));
    ASSERT_EQ(v, i);
  }
}

TEST(SpscRing, TwoThreadsDeliverEveryValueOnceInOrder) {
  struct Item {
    std::uint64_t seq;
    std::uint64_t check;  // a torn read would break seq * 7 + 3
  };
  constexpr std::uint64_t kCount = 200'000;
  SpscRing<Item> ring(64);  // small: producer and consumer keep meeting at the boundaries
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kCount; ++i) {
      while (!ring.TryPush(Item{i, i * 7 + 3})) std::this_thread::yield();
    }
  });
  std::uint64_t expected = 0;
  std::uint64_t bad = 0;
  Item it{};
  while (expected < kCount) {
    if (!ring.TryPop(it)) {
      std::this_thread::yield();
      continue;
    }
    if (it.seq != expected || it.check != it.seq * 7 + 3) ++bad;
    expected = it.seq + 1;
  }
  producer.join();
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(expected, kCount);
  EXPECT_FALSE(ring.TryPop(it));
}

TEST(Deadlines, TimespecRoundTrip) {
  using realtime::NsToTimespec;
  using realtime::TimespecToNs;
  const timespec a = NsToTimespec(3'000'000'123);
  EXPECT_EQ(a.tv_sec, 3);
  EXPECT_EQ(a.tv_nsec, 123);
  EXPECT_EQ(TimespecToNs(a), 3'000'000'123);
  const timespec b = NsToTimespec(999'999'999);
  EXPECT_EQ(b.tv_sec, 0);
  EXPECT_EQ(b.tv_nsec, 999'999'999);
  const timespec c = NsToTimespec(-1);  // normalised: tv_nsec stays in [0, 1e9)
  EXPECT_EQ(c.tv_sec, -1);
  EXPECT_EQ(c.tv_nsec, 999'999'999);
  EXPECT_EQ(TimespecToNs(c), -1);
}

TEST(Deadlines, PeriodicDeadlinesDoNotAccumulateRounding) {
  using realtime::PeriodicDeadlineNs;
  // A period of 1/3 ms in ns is not exact; deadlines come from k, not from summing periods.
  const std::int64_t start = 5'000'000'000;
  EXPECT_EQ(PeriodicDeadlineNs(start, 333'333, 0), start);
  EXPECT_EQ(PeriodicDeadlineNs(start, 333'333, 3'000'000), start + 999'999'000'000);
  EXPECT_EQ(PeriodicDeadlineNs(start, 1'000'000, 10'000), start + 10'000'000'000);
}

TEST(Deadlines, NextPeriodIndexSkipsMissedDeadlines) {
  using realtime::NextPeriodIndex;
  EXPECT_EQ(NextPeriodIndex(1000, 100, 0), 0);     // before the start
  EXPECT_EQ(NextPeriodIndex(1000, 100, 1000), 1);  // exactly on deadline 0: next is 1
  EXPECT_EQ(NextPeriodIndex(1000, 100, 1099), 1);
  EXPECT_EQ(NextPeriodIndex(1000, 100, 1100), 2);
  EXPECT_EQ(NextPeriodIndex(1000, 100, 1950), 10);  // overran nine periods
}

TEST(Deadlines, SleepUntilPastInstantReturnsAtOnceAndRejectsNegative) {
  EXPECT_EQ(realtime::SleepUntilNs(0), 0);
  EXPECT_EQ(realtime::SleepUntilNs(-5), EINVAL);
  const std::int64_t now = realtime::MonotonicNowNs();
  EXPECT_EQ(realtime::SleepUntilNs(now + 1000), 0);
  EXPECT_GE(realtime::MonotonicNowNs(), now + 1000);  // never returns early
}

TEST(Deadlines, HybridWaitNeverReturnsBeforeTheDeadline) {
  // Margins from none to longer than the wait itself; deadlines past, present and ahead.
  for (const std::int64_t spin_ns : {std::int64_t{0}, std::int64_t{1}, std::int64_t{20'000},
                                     std::int64_t{200'000}, std::int64_t{5'000'000}}) {
    for (const std::int64_t ahead_ns :
         {std::int64_t{-1'000'000}, std::int64_t{0}, std::int64_t{30'000}, std::int64_t{300'000}}) {
      const std::int64_t deadline = realtime::MonotonicNowNs() + ahead_ns;
      const std::int64_t returned = realtime::WaitUntilNs(deadline, spin_ns);
      EXPECT_GE(returned, deadline) << spin_ns << " " << ahead_ns;
      EXPECT_GE(realtime::MonotonicNowNs(), returned);  // the returned instant was read, not made
    }
  }
  // A negative instant (the sleep would fail with EINVAL) returns at once, still not early.
  EXPECT_GE(realtime::WaitUntilNs(-5, 0), -5);
  EXPECT_GE(realtime::WaitUntilNs(-5, 100), -5);
}

TEST(Deadlines, BareTimerMeasurementHasOneNonNegativeErrorPerWait) {
  for (const std::int64_t spin_ns : {std::int64_t{0}, std::int64_t{50'000}}) {
    const std::vector<std::int64_t> errors = realtime::MeasureWakeErrorsNs(100'000, 20, spin_ns);
    ASSERT_EQ(errors.size(), 20u);
    for (const std::int64_t e : errors) EXPECT_GE(e, 0);
  }
  EXPECT_THAT(realtime::MeasureWakeErrorsNs(100'000, 0, 0), IsEmpty());
  EXPECT_THAT(realtime::MeasureWakeErrorsNs(0, 5, 0), IsEmpty());
}

// Asks only for a timer slack (no SCHED_FIFO, no mlockall, no pinning: any thread may) on a
// thread of its own, so the settings stay with that thread; `slack_before_ns` gets that
// thread's slack before the call.
realtime::RealtimeStatus ApplySlackOnNewThread(long slack_ns, long* slack_before_ns = nullptr) {
  realtime::RealtimeStatus status;
  std::thread t([&] {
    if (slack_before_ns != nullptr) *slack_before_ns = ::prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0);
    realtime::RealtimeOptions o;
    o.sched_fifo = false;
    o.lock_memory = false;
    o.timer_slack_ns = slack_ns;
    status = realtime::ApplyRealtimeSettings(o);
  });
  t.join();
  return status;
}

TEST(RealtimeSettings, TimerSlackIsSetToOneNanosecondAndReported) {
  const realtime::RealtimeStatus status = ApplySlackOnNewThread(1);
  EXPECT_EQ(status.timer_slack_ns, 1);
  EXPECT_THAT(status.notes, IsEmpty());
  EXPECT_FALSE(status.sched_fifo);
  EXPECT_FALSE(status.memory_locked);
  EXPECT_EQ(status.pinned_cpu, -1);
  // timer_slack_ns = 0 leaves the thread's slack alone (the default of a new thread: 50 µs
  // unless the process was started with another).
  long before = -2;
  const realtime::RealtimeStatus untouched = ApplySlackOnNewThread(0, &before);
  EXPECT_EQ(untouched.timer_slack_ns, before);
}

class RecordingSink final : public realtime::FrameSink {
 public:
  std::error_code Send(const bus::CanFrame& frame) noexcept override {
    if (frame.id == 0x666) return std::make_error_code(std::errc::no_buffer_space);
    ids.push_back(frame.id);  // reserved by the test: no allocation here
    return {};
  }
  std::vector<std::uint32_t> ids;
};

TEST(FramePacer, SendsEveryFrameInOrderAndRecordsEach) {
  SpscRing<PacedFrame> input(16);
  SpscRing<SendRecord> records(16);
  RecordingSink sink;
  sink.ids.reserve(16);
  for (std::uint32_t i = 0; i < 5; ++i) {
    PacedFrame f;
    f.frame.id = i == 3 ? 0x666 : 0x100 + i;
    f.nominal_ns = i * 20'000;
    ASSERT_TRUE(input.TryPush(f));
  }
  std::atomic<bool> done{true}, stop{false};
  realtime::FramePacer pacer(input, records, sink);
  const realtime::PacerStats stats = pacer.Run(realtime::MonotonicNowNs(), done, stop);
  EXPECT_EQ(stats.sent, 4u);
  EXPECT_EQ(stats.send_errors, 1u);
  EXPECT_EQ(stats.records_dropped, 0u);
  EXPECT_THAT(sink.ids, ElementsAre(0x100, 0x101, 0x102, 0x104));
  SendRecord r;
  std::vector<SendRecord> got;
  while (records.TryPop(r)) got.push_back(r);
  ASSERT_EQ(got.size(), 5u);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].nominal_ns, static_cast<std::int64_t>(i) * 20'000);
    EXPECT_GE(got[i].woke_ns, got[i].nominal_ns);  // absolute sleeps never wake early
    EXPECT_GE(got[i].sent_ns, got[i].woke_ns);
  }
  EXPECT_EQ(got[3].error, ENOBUFS);
  EXPECT_EQ(got[4].error, 0);
}

TEST(FramePacer, HybridWaitSendsNoFrameBeforeItsDeadline) {
  SpscRing<PacedFrame> input(16);
  SpscRing<SendRecord> records(16);
  RecordingSink sink;
  sink.ids.reserve(16);
  for (std::uint32_t i = 0; i < 6; ++i) {
    PacedFrame f;
    f.frame.id = 0x200 + i;
    f.nominal_ns = i * 150'000;  // spaced wider than the margin: each wait sleeps, then spins
    ASSERT_TRUE(input.TryPush(f));
  }
  std::atomic<bool> done{true}, stop{false};
  realtime::FramePacer pacer(input, records, sink, /*spin_ns=*/100'000);
  const realtime::PacerStats stats = pacer.Run(realtime::MonotonicNowNs(), done, stop);
  EXPECT_EQ(stats.sent, 6u);
  SendRecord r;
  int n = 0;
  while (records.TryPop(r)) {
    EXPECT_GE(r.woke_ns, r.nominal_ns) << n;
    EXPECT_GE(r.sent_ns, r.woke_ns) << n;
    ++n;
  }
  EXPECT_EQ(n, 6);
}

TEST(FramePacer, CountsRecordsTheWriterCouldNotTake) {
  SpscRing<PacedFrame> input(8);
  SpscRing<SendRecord> records(2);
  RecordingSink sink;
  sink.ids.reserve(8);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(input.TryPush(PacedFrame{}));
  std::atomic<bool> done{true}, stop{false};
  realtime::FramePacer pacer(input, records, sink);
  const realtime::PacerStats stats = pacer.Run(realtime::MonotonicNowNs(), done, stop);
  EXPECT_EQ(stats.sent, 5u);
  EXPECT_EQ(stats.records_dropped, 3u);
}

TEST(Paper002DeviceSet, OneCycleHasSyncThreeTpdosAccelAndImuInBusOrder) {
  bench::Paper002DeviceSetOptions o;
  o.source_dir = WHEELHIL_SOURCE_DIR;
  bench::Paper002DeviceSet devices(o);
  std::vector<PacedFrame> frames;
  for (int c = 0; c < 20; ++c) devices.NextCycle(frames);
  EXPECT_EQ(devices.problems(), 0u);
  std::map<std::uint32_t, int> count;
  for (const auto& f : frames) ++count[f.frame.id];
  // 20 cycles: SYNC + 3 TPDO + accel each; MM5.10 every 10 cycles. The last cycle's tail may
  // still be on the modelled bus.
  EXPECT_GE(count[0x080], 19);
  EXPECT_LE(count[0x080], 20);
  for (std::uint32_t id : {0x181u, 0x182u, 0x183u, 0x170u}) {
    EXPECT_GE(count[id], 19) << std::hex << id;
    EXPECT_LE(count[id], 20) << std::hex << id;
  }
  for (std::uint32_t id : {0x174u, 0x178u, 0x17Cu}) EXPECT_EQ(count[id], 2) << std::hex << id;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    ASSERT_GE(frames[i].nominal_ns, frames[i - 1].nominal_ns) << i;
  }
  // Each frame's SOF lies at or after its cycle's SYNC; at 1 Mbit/s no two frames overlap.
  for (std::size_t i = 1; i < frames.size(); ++i) {
    EXPECT_GE(frames[i].nominal_ns - frames[i - 1].nominal_ns, 47'000) << i;
  }
}

TEST(Paper002DeviceSet, AccelFramesDecodeThroughTheDbcWithCounterAndChecksum) {
  bench::Paper002DeviceSetOptions o;
  o.source_dir = WHEELHIL_SOURCE_DIR;
  bench::Paper002DeviceSet devices(o);
  std::vector<PacedFrame> frames;
  for (int c = 0; c < 100; ++c) devices.NextCycle(frames);  // 0.1 s: accelerating at 0.5 m/s^2
  const auto db =
      bus::DbcDatabase::LoadFile(std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc/wheelhil_accel4.dbc");
  const bus::DbcMessage* m = db.FindMessage(0x170, false);
  ASSERT_NE(m, nullptr);
  int n = 0;
  int last_counter = -1;
  double sum_a1 = 0, sum_a4 = 0;
  for (const auto& f : frames) {
    if (f.frame.id != 0x170) continue;
    std::uint8_t x = static_cast<std::uint8_t>(f.frame.data[7] & 0x0F);
    for (int i = 0; i < 7; ++i) {
      x ^= static_cast<std::uint8_t>((f.frame.data[i] & 0x0F) ^ (f.frame.data[i] >> 4));
    }
    EXPECT_EQ(x, f.frame.data[7] >> 4);
    const auto v = bus::DecodeMessage(*m, f.frame);
    const int counter = static_cast<int>(v.at("ACC4_Counter"));
    if (last_counter >= 0) {
      EXPECT_EQ(counter, (last_counter + 1) % 16);
    }
    last_counter = counter;
    sum_a1 += v.at("ACC4_A1");
    sum_a4 += v.at("ACC4_A4");
    ++n;
  }
  ASSERT_GE(n, 99);
  // Paper 002 eq 3 with ath = 0: a1 = ax = 0.5, a4 = -ax. Noise 0.002 m/s^2/sqrt(Hz) at 1 kHz
  // is 0.063 m/s^2 per sample, 0.0063 for the mean of 100: 5 sigma = 0.032.
  EXPECT_NEAR(sum_a1 / n, 0.5, 0.032);
  EXPECT_NEAR(sum_a4 / n, -0.5, 0.032);
}

TEST(Paper002DeviceSet, BadSourceDirThrows) {
  bench::Paper002DeviceSetOptions o;
  o.source_dir = "/nonexistent";
  EXPECT_THROW(bench::Paper002DeviceSet devices(o), std::invalid_argument);
}

TEST(BenchReport, CpuModelFromCpuinfo) {
  EXPECT_EQ(bench::CpuModelFromCpuinfo("processor\t: 0\nmodel name\t: AMD EPYC 7B13\nflags\t: x\n"),
            "AMD EPYC 7B13");
  EXPECT_EQ(bench::CpuModelFromCpuinfo("processor : 0\nHardware : BCM2835\n"), "BCM2835");
  EXPECT_EQ(bench::CpuModelFromCpuinfo(""), "unknown");
  EXPECT_EQ(bench::CpuModelFromCpuinfo("model name\t:\n"), "unknown");
}

TEST(BenchReport, MachineFactsAreFilled) {
  const bench::MachineFacts m = bench::ReadMachineFacts();
  EXPECT_FALSE(m.cpu_model.empty());
  EXPECT_GE(m.cores, 1);
  EXPECT_FALSE(m.build_type.empty());
  EXPECT_EQ(m.date_utc.size(), 20u);
}

TEST(BenchReport, PercentileIsNearestRank) {
  std::vector<double> v;
  for (int i = 100; i >= 1; --i) v.push_back(i);
  EXPECT_DOUBLE_EQ(bench::Percentile(v, 50), 50);
  EXPECT_DOUBLE_EQ(bench::Percentile(v, 99), 99);
  EXPECT_DOUBLE_EQ(bench::Percentile(v, 100), 100);
  EXPECT_DOUBLE_EQ(bench::Percentile(v, 0), 1);
  EXPECT_DOUBLE_EQ(bench::Median({3, 1, 2}), 2);
  EXPECT_TRUE(std::isnan(bench::Percentile({}, 50)));
}

TEST(BenchReport, PathsAndUnavailable) {
  nlohmann::json r = nlohmann::json::object();
  bench::SetPath(r, "physics.diff2.flat_rtf", 600.0);
  bench::SetPath(r, "bus.vcan_frames_per_s", bench::Unavailable("no vcan0"));
  EXPECT_DOUBLE_EQ(r["physics"]["diff2"]["flat_rtf"].get<double>(), 600.0);
  ASSERT_NE(bench::GetPath(r, "bus.vcan_frames_per_s"), nullptr);
  EXPECT_TRUE(bench::IsUnavailable(*bench::GetPath(r, "bus.vcan_frames_per_s")));
  EXPECT_FALSE(bench::IsUnavailable(nlohmann::json("unavailable: ")));  // a reason is required
  EXPECT_FALSE(bench::IsUnavailable(nlohmann::json(1.0)));
  EXPECT_EQ(bench::GetPath(r, "physics.diff2.mesh_rtf"), nullptr);
  EXPECT_EQ(bench::GetPath(r, "physics.diff2.flat_rtf.x"), nullptr);
}

nlohmann::json CompleteReport() {
  nlohmann::json r = nlohmann::json::object();
  for (const auto& k : bench::DocumentedMetricKeys()) bench::SetPath(r, k, 1.5);
  for (const auto& k : bench::DocumentedTextKeys()) bench::SetPath(r, k, "x");
  return r;
}

TEST(BenchReport, KeySetNamesEveryRequiredFigure) {
  const auto keys = bench::DocumentedMetricKeys();
  for (const char* k : {"physics.diff2.flat_rtf",
                        "physics.diff2.mesh_rtf",
                        "physics.mecanum4_omni3.flat_rtf",
                        "physics.ortho3.mesh_rtf",
                        "physics.platforms_1.rtf",
                        "physics.platforms_4.rtf",
                        "physics.platforms_16.rtf",
                        "lockstep.paper000.rtf",
                        "lockstep.paper002.rtf",
                        "lockstep.paper002.vcan_rtf",
                        "bus.ucan_frames_per_s",
                        "bus.ucan_fanout4_frames_per_s",
                        "bus.vcan_frames_per_s",
                        "bus.ucan_vs_vcan_ratio",
                        "realtime.p50_us",
                        "realtime.p99_us",
                        "realtime.max_us",
                        "realtime.missed_deadlines",
                        "rss.peak_mib",
                        "machine.cores"}) {
    EXPECT_THAT(keys, ::testing::Contains(std::string(k)));
  }
  const auto text = bench::DocumentedTextKeys();
  EXPECT_THAT(text, ::testing::Contains(std::string("machine.cpu_model")));
  EXPECT_THAT(text, ::testing::Contains(std::string("machine.build_type")));
}

TEST(BenchReport, CheckAcceptsCompleteAndUnavailableRejectsMissingNanAndBareStrings) {
  nlohmann::json r = CompleteReport();
  EXPECT_THAT(bench::CheckReport(r), IsEmpty());
  bench::SetPath(r, "bus.vcan_frames_per_s", bench::Unavailable("no vcan0"));
  EXPECT_THAT(bench::CheckReport(r), IsEmpty());
  r["realtime"].erase("p99_us");
  bench::SetPath(r, "physics.diff2.flat_rtf", "fast");
  bench::SetPath(r, "machine.cpu_model", 3);
  const auto problems = bench::CheckReport(r);
  ASSERT_EQ(problems.size(), 3u);
  EXPECT_THAT(problems[0], HasSubstr("physics.diff2.flat_rtf"));
  EXPECT_THAT(problems[1], HasSubstr("realtime.p99_us: missing"));
  EXPECT_THAT(problems[2], HasSubstr("machine.cpu_model"));
  nlohmann::json n = CompleteReport();
  bench::SetPath(n, "rss.peak_mib", std::numeric_limits<double>::quiet_NaN());
  EXPECT_THAT(bench::CheckReport(n), ElementsAre(HasSubstr("rss.peak_mib")));
}

TEST(BenchReport, TableListsEveryKey) {
  const std::string table = bench::FormatTable(CompleteReport());
  for (const auto& k : bench::DocumentedMetricKeys()) EXPECT_THAT(table, HasSubstr(k));
  for (const auto& k : bench::DocumentedTextKeys()) EXPECT_THAT(table, HasSubstr(k));
}

TEST(BenchReport, DocsPerformanceMdDocumentsEveryKey) {
  std::ifstream in(std::string(WHEELHIL_SOURCE_DIR) + "/docs/performance.md");
  ASSERT_TRUE(in) << "docs/performance.md is missing";
  const std::string doc((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const auto& k : bench::DocumentedMetricKeys()) {
    EXPECT_THAT(doc, HasSubstr("`" + k + "`"));
  }
  for (const auto& k : bench::DocumentedTextKeys()) {
    EXPECT_THAT(doc, HasSubstr("`" + k + "`"));
  }
}

}  // namespace
}  // namespace wheelhil::emulator

namespace wheelhil::emulator::bench {
namespace {

// A bench worker that overstays its limit (a run that never ends) costs its row, not the bench:
// it is killed with the processes it started, and the row says why.
TEST(BenchWorker, AWorkerThatOverstaysIsKilledWithWhatItStarted) {
  const auto t0 = std::chrono::steady_clock::now();
  const WorkerOutcome w =
      RunWorkerProcess({"/bin/sh", "-c", "sleep 30 & sleep 30"}, {}, /*expect_json=*/false, 0.5);
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(took_s, 10.0);  // not the sleeps' 30 s: the background one holds the pipe too
  EXPECT_THAT(w.problem, ::testing::HasSubstr("`-c sleep 30 & sleep 30` did not finish within "
                                              "0.5 s of wall time (killed)"));
}

}  // namespace
}  // namespace wheelhil::emulator::bench
