// Userspace CAN bus throughput: one writer -> N readers, 8-byte classic frames, through the
// plain SocketCAN API (this binary links libwheelhil_ucan.so) and an in-process UcanBroker.
// Flow-controlled (at most kWindow frames in flight to the slowest reader), so the numbers are
// frames delivered to every reader, never frames dropped; a run with drops is an error.
//   build-*/bin/ucan_bench --benchmark_min_time=2

#include <linux/can.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <unistd.h>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <string>
#include <vector>

#include "bus/ucan_broker.h"
#include "emulator/bench/fan_out_readers.h"

namespace {

using wheelhil::emulator::bench::FanOutReaders;
using wheelhil::emulator::bench::OpenRawCan;

constexpr std::uint64_t kWindow = 2048;

void BM_UcanFanOut(benchmark::State& state) {
  const int readers = static_cast<int>(state.range(0));
  char tmpl[] = "/tmp/wheelhil-ucan-bench-XXXXXX";
  const std::string dir = ::mkdtemp(tmpl);
  ::setenv("WHEELHIL_UCAN_DIR", dir.c_str(), 1);
  {
    wheelhil::bus::UcanBrokerOptions options;
    options.runtime_dir = dir;
    wheelhil::bus::UcanBroker broker(options);
    broker.AddBus("ucan0");
    const int tx = OpenRawCan("ucan0");
    std::vector<int> rx;
    for (int i = 0; i < readers; ++i) rx.push_back(OpenRawCan("ucan0"));
    if (tx < 0 || std::count(rx.begin(), rx.end(), -1) > 0) {
      state.SkipWithError("cannot open ucan0");
    }

    FanOutReaders reader_threads(rx);
    can_frame f{};
    f.can_id = 0x123;
    f.can_dlc = 8;
    std::uint64_t sent = 0;
    for (auto _ : state) {
      // The writer sleeps while the window is full: no CPU taken from the readers.
      if (!reader_threads.WaitForWindow(sent, kWindow,
                                        FanOutReaders::Clock::now() + std::chrono::seconds(10))) {
        state.SkipWithError("a reader stalled for 10 s");
        break;
      }
      std::memcpy(f.data, &sent, sizeof(sent));
      if (::write(tx, &f, sizeof(f)) != sizeof(f)) {
        state.SkipWithError("write failed");
        break;
      }
      ++sent;
    }
    if (!reader_threads.WaitForAll(sent, 10.0)) state.SkipWithError("frames never arrived");
    if (broker.Stats().at(0).drops != 0) state.SkipWithError("frames were dropped");
    reader_threads.Stop();
    ::close(tx);
    for (int fd : rx) {
      if (fd >= 0) ::close(fd);
    }
    state.SetItemsProcessed(static_cast<std::int64_t>(sent));
    state.counters["deliveries_per_s"] =
        benchmark::Counter(static_cast<double>(sent) * readers, benchmark::Counter::kIsRate);
  }
  const std::string rm = "rm -rf '" + dir + "'";
  [[maybe_unused]] int rc = std::system(rm.c_str());
}
BENCHMARK(BM_UcanFanOut)->Arg(1)->Arg(4)->UseRealTime()->Unit(benchmark::kMicrosecond);

// Baseline: what this kernel charges for one AF_UNIX SOCK_SEQPACKET message (send + receive of
// 40 bytes, one thread, no wakeups). A ucan frame costs two of these (writer -> broker ->
// reader), so 1 / (2 x this time) per core bounds the bus whatever the broker does.
void BM_KernelSeqpacketMessage(benchmark::State& state) {
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) != 0) {
    state.SkipWithError("socketpair failed");
    return;
  }
  char buf[40] = {};
  for (auto _ : state) {
    if (::send(sv[0], buf, sizeof(buf), 0) != sizeof(buf) ||
        ::recv(sv[1], buf, sizeof(buf), 0) != sizeof(buf)) {
      state.SkipWithError("send/recv failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
  ::close(sv[0]);
  ::close(sv[1]);
}
BENCHMARK(BM_KernelSeqpacketMessage)->UseRealTime()->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
