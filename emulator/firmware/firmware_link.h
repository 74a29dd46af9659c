#pragma once
/// The run's connection to the firmware's CAN interface. By default a private userspace bus:
/// a UcanBroker on "ucan0" in a fresh runtime directory (exported as WHEELHIL_UCAN_DIR; the
/// firmware reaches it through the SocketCAN interposition library). In lockstep the run's own
/// thread routes that bus (UcanBroker::Pump) through an in-process port, so a turn costs two
/// context switches (to the firmware and back) rather than one per hop through a broker thread;
/// otherwise, and on a kernel interface (--can vcan0), a SocketCAN socket.
/// Frames to the firmware go out with Send; the firmware's frames come in only while the run
/// settles it (Settle, virtual clock) or drains it (Drain, real time), handed to the frame
/// callback.
/// Run-time failures (the bus stopped, the firmware exited) go to the RunContext.
/// Thread-compatible (one run per process: it sets WHEELHIL_UCAN_DIR in this process).

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "bus/can_frame.h"
#include "bus/socketcan_transport.h"
#include "bus/ucan_broker.h"
#include "emulator/firmware/firmware_process.h"
#include "emulator/firmware/virtual_clock.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::firmware {

class FirmwareLink {
 public:
  using FrameFn = std::function<void(const bus::CanFrame&)>;

  /// How the run meets the firmware: at wall-clock instants, or in lockstep on the firmware's
  /// virtual clock (Settle; the private bus then tells its ring clients that every pass drains
  /// their frames, so they send no doorbells).
  enum class Pacing { kRealTime, kVirtualClock };

  /// `can_iface` empty: the private userspace bus. Throws what the transport throws for a
  /// kernel interface that cannot be opened.
  FirmwareLink(const std::string& can_iface, Pacing pacing, sim::RunContext& run);
  ~FirmwareLink();

  const std::string& interface() const { return iface_; }
  bool private_bus() const { return broker_ != nullptr; }
  const std::string& runtime_dir() const { return runtime_dir_; }

  /// Remembers what a kernel bus had before the firmware starts (see WaitForConnection).
  void BeforeFirmwareStarts();
  /// Waits (wall clock, up to timeout_s) until the firmware opened the interface; false with
  /// `why` when it exited before or never did.
  bool WaitForConnection(FirmwareProcess& process, double timeout_s, std::string& why);

  /// A frame for the firmware; false when it could not be handed over.
  bool Send(const bus::CanFrame& frame);
  /// Real time: hands over what the firmware sent so far, waiting at most timeout_ms for it.
  void Drain(int timeout_ms, const FrameFn& on_frame);
  /// Virtual time (pumped bus): ends the firmware's waits due at the clock's time, then routes
  /// the bus and hands over the firmware's frames until every firmware thread is blocked and
  /// a last pass moves nothing. False (the reason in the RunContext) when the firmware exited
  /// or did not block within timeout_s of wall time (its running threads are named).
  bool Settle(VirtualClock& clock, double timeout_s, FirmwareProcess& process,
              const FrameFn& on_frame);
  /// Runahead (docs/virtual-time.md): a frame for the firmware at run time instant_ns, put in
  /// its sockets' rings ahead (bus::UcanBroker::PrepareLocal); false when it could not be.
  bool Prepare(const bus::CanFrame& frame, std::int64_t instant_ns);
  /// Runahead: with the clock granted to the firmware, waits (wall clock) until it gave the
  /// clock back and every thread of it is blocked, then delivers the frames it published and
  /// drops the rest (bus::UcanBroker::SettlePrepared). A turn of the firmware's. False (the
  /// reason in the RunContext) as Settle.
  bool RunAhead(VirtualClock& clock, double timeout_s, FirmwareProcess& process);
  /// Runahead, while the run catches up with a firmware ahead of it: hands `on_frame` the next
  /// `frames` frames the firmware sent (its sends that did not end the window, in order).
  void TakeSent(std::size_t frames, const FrameFn& on_frame);
  /// Runahead: what the firmware sends reaches the run alone (one socket, not taking its own
  /// frames), so a send of its changes nothing it is handed but through the bus.
  bool SendsReachOnlyTheRun() const;
  /// Runahead not begun after all: the frames put ahead go.
  std::uint64_t RunAheadDropPrepared() { return broker_ ? broker_->SettlePrepared() : 0; }
  /// Virtual time, after the run: ends the waits due, routes the bus (the firmware's frames are
  /// dropped) and waits up to 1 ms for the firmware to change.
  void KeepAlive(VirtualClock& clock);
  /// Virtual time: the frames' receive stamps are the clock's CLOCK_REALTIME, and every broker
  /// pass that wrote to the firmware tells the clock (VirtualClock::NoteFdWakes).
  void UseVirtualClock(VirtualClock& clock);
  /// Virtual time: the wall time of Settle's turns (not of a settle that finds the firmware
  /// still blocked with nothing for it) is added to `seconds`.
  void AccountHandoversIn(double& seconds) { handover_s_ = &seconds; }
  /// The firmware has a socket bound on the private bus (remembered: FailExited says whether it
  /// ever had one).
  bool FirmwareConnected();
  /// The firmware's turns so far: settles that did not find it still blocked with nothing
  /// new for it, and runahead windows.
  std::uint64_t handovers() const { return handovers_; }
  /// Closes the transport and the private bus (its runtime directory goes with it).
  void Close();

 private:
  // quiet: UcanBroker::PumpQuiet (no look at the clients' sockets).
  void Pump(int timeout_ms, bool quiet = false);
  // One broker pass, told to the virtual clock when it wrote to a client (first_sent:
  // UcanBroker::PumpFirstSent).
  bool PumpBroker(int timeout_ms, bool quiet = false, std::size_t first_sent = SIZE_MAX);
  // Virtual clock on a kernel bus: writes the frames Send kept for the settle.
  void SendToKernel();
  // Virtual clock on a kernel bus: hands `on_frame` the firmware's frames, after the kernel
  // delivered every frame the run sent and every frame the firmware sent (as its clock library
  // counted them); fails the run when that takes kKernelDeliverySeconds.
  void TakeKernelFrames(const FrameFn& on_frame);
  // Fails the run when the private bus refused a connection (the firmware hit a broker limit).
  void CheckBrokerLimits();
  // Waiting wall_s for the firmware to block: after min(1 s, timeout/2) its exit is looked for
  // and who runs is told (event firmware_busy); after timeout_s the run fails naming its
  // running threads. False when the run failed.
  bool StillWaiting(VirtualClock& clock, double wall_s, double timeout_s, FirmwareProcess& process,
                    bool& checked_exit);
  // "the firmware was killed by signal 11 (SIGSEGV) during the run (see firmware.log)".
  void FailExited(const FirmwareProcess& process);

  sim::RunContext& run_;
  std::string iface_;
  std::string runtime_dir_;
  std::unique_ptr<bus::UcanBroker> broker_;
  std::optional<bus::SocketCanTransport> can_;
  bool pumped_ = false;
  int local_port_ = -1;  // the emulator's port on the pumped bus
  VirtualClock* clock_ = nullptr;  // UseVirtualClock
  double* handover_s_ = nullptr;   // AccountHandoversIn
  bus::UcanWokenClients woken_;    // PumpBroker's scratch
  static constexpr int kMaxUnpumpedFrames = 32;
  // Settle: wall time at one virtual instant for a firmware that keeps blocking and being woken
  // by the bus: this many timeouts, and at least this many seconds.
  static constexpr double kTimeoutsAtOneInstant = 20;
  static constexpr double kMinSecondsAtOneInstant = 60;
  int unpumped_frames_ = 0;
  int kernel_receivers_before_ = -1;
  bool firmware_blocked_ = false;  // virtual time: at the end of the last Settle
  bool after_runahead_ = false;    // RunAhead: the next Settle picks up what it sent
  // Virtual clock on a kernel bus: the run's frames not back yet (ReceivedFrame::own), the
  // frames taken from others, and how long the kernel may take to deliver them.
  bool kernel_confirms_ = false;
  std::vector<bus::CanFrame> to_kernel_;  // Send's frames, written at the next Settle
  std::uint64_t unconfirmed_ = 0;
  std::uint64_t kernel_frames_in_ = 0;
  static constexpr double kKernelDeliverySeconds = 10;
  // Virtual time, Settle: VirtualClock::socket_activity and the clock's time at the last pass
  // that looked at the broker's sockets.
  static constexpr std::int64_t kSocketLookEveryNs = 10'000'000;
  std::uint64_t activity_at_look_ = UINT64_MAX;
  std::int64_t last_look_ns_ = 0;
  bool opened_once_ = false;  // the firmware bound a socket once (FirmwareConnected)
  std::uint64_t handovers_ = 0;
};

/// CAN receivers the kernel has registered on `iface` (one per filter of every bound CAN
/// socket), from /proc/net/can/rcvlist_*; -1 when none of those lists can be read.
int CountKernelCanReceivers(const std::string& iface);

}  // namespace wheelhil::emulator::firmware
