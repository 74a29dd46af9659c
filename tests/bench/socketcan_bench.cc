// SocketCAN transport throughput. The kernel benchmarks need a vcan: run them in the
// user-mode-linux guest,
//   tests/vcan/uml_run.sh -- build/bin/socketcan_bench
// (or on a host with an up vcan and WHEELHIL_VCAN=vcan0); without one they report an error and
// only the frame conversion benchmark runs.

#include <benchmark/benchmark.h>

#include <atomic>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "bus/internal/socketcan_convert.h"
#include "bus/socketcan_transport.h"

namespace wheelhil::bus {
namespace {

const char* VcanName() {
  const char* name = std::getenv("WHEELHIL_VCAN");
  return name != nullptr && *name != '\0' ? name : nullptr;
}

CanFrame EightBytes(std::uint32_t id) {
  const std::vector<std::uint8_t> b{1, 2, 3, 4, 5, 6, 7, 8};
  return CanFrame::Classic(id, b);
}

// 1 writer thread -> 1 reader thread on the same vcan, 8-byte classic frames, in batches of
// range(0) frames. items_per_second = frames received per second; `lost` = frames the reader
// never saw (receive-queue overflow), `retries` = writes retried after ENOBUFS/EAGAIN.
void BM_VcanWriterToReader(benchmark::State& state) {
  const char* iface = VcanName();
  if (iface == nullptr) {
    state.SkipWithError("set WHEELHIL_VCAN=vcan0 (run under tests/vcan/uml_run.sh)");
    return;
  }
  const int batch = static_cast<int>(state.range(0));
  SocketCanTransport tx = SocketCanTransport::Open(iface);
  CanTransportOptions rx_opt;
  rx_opt.filters = {{.id = 0x123, .mask = 0x7FF}};  // Ignore traffic from anyone else.
  SocketCanTransport rx = SocketCanTransport::Open(iface, rx_opt);
  const CanFrame frame = EightBytes(0x123);
  std::int64_t received = 0;
  std::int64_t sent = 0;
  for (auto _ : state) {
    std::atomic<int> got{0};
    std::thread reader([&] {
      ReceivedFrame rf;
      int n = 0;
      while (n < batch) {
        const std::error_code ec = rx.Receive(rf, 100);
        if (!ec) {
          ++n;
        } else if (ec == std::errc::timed_out) {
          break;  // The rest were lost.
        }
      }
      got.store(n);
    });
    for (int i = 0; i < batch; ++i) sent += tx.Send(frame) ? 0 : 1;
    reader.join();
    received += got.load();
  }
  state.SetItemsProcessed(received);
  state.counters["lost"] = static_cast<double>(sent - received);
  state.counters["retries"] = static_cast<double>(tx.stats().send_retries);
  state.counters["kernel_drops"] = static_cast<double>(rx.stats().rx_kernel_drops);
}
BENCHMARK(BM_VcanWriterToReader)->Arg(64)->Arg(256)->UseRealTime()->Unit(benchmark::kMillisecond);

// One thread: Send() then Receive() of that frame on a second socket (per-frame round trip
// through the kernel, no batching).
void BM_VcanSendThenReceive(benchmark::State& state) {
  const char* iface = VcanName();
  if (iface == nullptr) {
    state.SkipWithError("set WHEELHIL_VCAN=vcan0 (run under tests/vcan/uml_run.sh)");
    return;
  }
  SocketCanTransport tx = SocketCanTransport::Open(iface);
  CanTransportOptions rx_opt;
  rx_opt.filters = {{.id = 0x124, .mask = 0x7FF}};
  SocketCanTransport rx = SocketCanTransport::Open(iface, rx_opt);
  const CanFrame frame = EightBytes(0x124);
  ReceivedFrame rf;
  for (auto _ : state) {
    if (tx.Send(frame) || rx.Receive(rf, 1000)) {
      state.SkipWithError("frame lost");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_VcanSendThenReceive)->UseRealTime();

// CanFrame -> struct can_frame -> CanFrame, no kernel involved.
void BM_EncodeDecode(benchmark::State& state) {
  const CanFrame frame = EightBytes(0x125);
  canfd_frame buf;
  CanFrame back;
  for (auto _ : state) {
    const std::size_t n = internal::EncodeFrame(frame, buf);
    benchmark::DoNotOptimize(internal::DecodeFrame(&buf, n, back));
    benchmark::DoNotOptimize(back);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_EncodeDecode);

}  // namespace
}  // namespace wheelhil::bus

BENCHMARK_MAIN();
