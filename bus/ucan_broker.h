#pragma once
/// The userspace CAN bus broker: owns named buses (`ucan0`, ...) that programs reach through
/// the SocketCAN API when bus/ucan_interpose.cc (libwheelhil_ucan.so) is preloaded or linked.
/// Serves `<runtime dir>/ucan.sock` (see bus/ucan_protocol.h) from one epoll thread.
///
/// Semantics follow vcan: a frame written by one socket reaches every other socket on the bus
/// (and sockets bound to "any", ifindex 0) whose CAN_RAW filters match, in one global order per
/// bus; the sender sees it only with CAN_RAW_RECV_OWN_MSGS; with CAN_RAW_LOOPBACK off, sockets
/// of the sender's own process do not see it (other processes are other nodes on the bus).
/// Each reader has a bounded queue (kernel socket buffer + `client_queue_limit` messages);
/// overflow is dropped for that reader only and counted (per bus in Stats(), per socket through
/// SO_RXQ_OVFL). Bad client messages are counted and ignored; they never reach other clients.
///
/// Clients are not trusted (bus/ucan_protocol.h): a request acts only on the connection whose
/// token it quotes (never on an in-process port), ring geometry and the broker's ring indexes
/// never come from shared memory, a client writing impossible indexes is disconnected, and
/// connections are limited in total and per process. Past a limit, or out of file descriptors,
/// a new connection is answered EMFILE and closed; one that sends no request within
/// `request_timeout_ms` is closed. Each pass accepts a bounded number of connections, so a flood
/// of them cannot hold the broker (or its lock) in one pass. All of it is counted in Health().
/// (Limits apply to socket clients; in-process ports are the owner's.)
///
/// Interface indexes are stable per runtime directory: "ucanN" -> 1000 + N, other names 2000 +
/// order of first creation (a removed and re-added bus keeps its index).
///
/// Thread-safety: all public methods may be called from any thread, except Pump() (the thread
/// that called UseCallerThread()).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include "bus/can_frame.h"

namespace wheelhil::bus {

struct UcanBrokerOptions {
  /// Runtime directory; empty: ResolveUcanRuntimeDir(). Created (mode 0700) when missing.
  std::string runtime_dir;
  /// Messages queued in the broker per reader once its socket buffer is full.
  std::size_t client_queue_limit = 8192;
  /// Stop the broker when the last bus is removed through a kRemoveBus request (daemon mode).
  bool exit_when_empty = false;
  /// On destruction also remove the lock file and the (then empty) runtime directory: for a
  /// private directory from CreateTempUcanRuntimeDir().
  bool remove_runtime_dir = false;
  /// Connections served at once, requests included (at most the fd limit less 64), and per
  /// client process (SO_PEERCRED pid).
  std::size_t max_connections = 1024;
  std::size_t max_connections_per_process = 256;
  /// A connection that sends no request within this many ms is closed.
  int request_timeout_ms = 5000;
  /// Control requests from clients (add/remove a bus, shut down). Off for a bus owned by a
  /// program (a run's private bus): those requests get EPERM.
  bool control_requests = true;
  /// The owner pumps the broker (UseCallerThread) and never waits in Pump() for a client's
  /// frame, so every pass drains the tx rings anyway: ring clients are told to send no tx
  /// doorbells (a system call per frame saved on their side and on the broker's). A Pump()
  /// with a timeout then does not end early for a frame sent through a ring.
  bool tx_rings_drained_every_pass = false;
};

/// What the broker refused or cut off to protect itself and its other clients.
struct UcanBrokerHealth {
  std::uint64_t refused_connections = 0;    ///< Over a limit, or out of fds: answered EMFILE.
  std::uint64_t silent_connections = 0;     ///< Closed: no request within the timeout.
  std::uint64_t corrupt_rings = 0;          ///< Disconnected: impossible shared-ring indexes.
  std::uint64_t refused_requests = 0;       ///< A wrong token, or control requests off.
  std::string last_refusal;                 ///< Why the last connection was refused.
};

struct UcanBusStats {
  std::string name;
  int ifindex = 0;
  std::size_t clients = 0;         ///< Sockets bound to this bus.
  std::uint64_t binds = 0;         ///< Sockets ever bound to it (this broker's Stats() only).
  std::uint64_t frames = 0;        ///< Frames accepted.
  std::uint64_t drops = 0;         ///< Deliveries dropped (a reader's queue was full).
  std::uint64_t bad_messages = 0;  ///< Rejected client messages (bad size or frame).
};

/// UcanBroker::TakeWokenClients.
struct UcanWokenClients {
  std::vector<std::uint32_t> ids;
  bool other = false;
};

class UcanBroker {
 public:
  /// Creates/verifies the runtime directory, takes its lock, binds the socket and starts the
  /// broker thread. Throws std::system_error when the directory is unsafe or unusable, or
  /// (errc::device_or_resource_busy) when another broker already serves it.
  explicit UcanBroker(UcanBrokerOptions options = {});
  ~UcanBroker();  ///< Stops the thread, disconnects clients, removes the socket.
  UcanBroker(const UcanBroker&) = delete;
  UcanBroker& operator=(const UcanBroker&) = delete;

  /// Adds a bus (idempotent) and returns its interface index. Throws std::invalid_argument for
  /// a name that is empty, longer than 15 characters, or contains '/', whitespace or ':'.
  int AddBus(const std::string& name);
  /// Removes a bus and disconnects its sockets (their reads/writes then fail with ENETDOWN).
  /// False when there is no such bus.
  bool RemoveBus(const std::string& name);
  std::vector<UcanBusStats> Stats() const;
  UcanBrokerHealth Health() const;

  /// Blocks until the broker stops (a kShutdown request, exit_when_empty, or Stop()).
  void Wait();
  void Stop();

  /// Ends the broker thread and leaves the routing to the caller, who from then on moves frames
  /// with Pump() (clients stay connected; nothing moves between two Pump() calls). For a
  /// lockstep owner that both sends and waits: one thread instead of two saves a context switch
  /// per hop. Idempotent; call from one thread only, not concurrently with Pump().
  void UseCallerThread();
  /// One broker pass on the calling thread, after UseCallerThread(): waits up to `timeout_ms`
  /// (0: not at all, -1: forever) for traffic, then accepts, reads and routes everything ready.
  /// False once the broker has stopped. Throws std::logic_error while the thread still runs.
  bool Pump(int timeout_ms);
  /// A pass that does not look at the clients' sockets (no system call unless it writes): it
  /// routes what SendLocal() queued and what the clients' rings hold. For an owner that knows
  /// no client can have written to its socket since its last Pump() (its programs were all
  /// blocked since), so that pass's look would find nothing.
  bool PumpQuiet();

  /// An in-process socket on `bus` for the owner that pumps: a CAN_RAW socket with a new
  /// socket's options (every frame, loopback on, its own frames not received) but no kernel
  /// socket, so a frame costs no system call on the owner's side. Frames sent are stamped at
  /// SendLocal() (their place in the bus order) and routed by the next Pump(); frames routed to
  /// the port wait for ReceiveLocal() (its queue is bounded like a client's: overflow counted
  /// as drops). Returns the port; throws std::invalid_argument for an unknown bus.
  int OpenLocalPort(const std::string& bus);
  /// False for an invalid frame (or an FD frame) or a closed port.
  bool SendLocal(int port, const CanFrame& frame);
  /// Takes the next frame routed to the port; false when none is there.
  bool ReceiveLocal(int port, CanFrame* frame);
  /// Runahead: a pass like PumpQuiet that routes only the first `frames` frames waiting in
  /// the clients' rings (in their order); the rest wait for a later pass. For an owner that
  /// takes what a program sent ahead of it, instant by instant. Call with none of the owner's
  /// own frames pending.
  bool PumpFirstSent(std::size_t frames);
  /// Runahead: a frame any client sends now reaches no other client (nor itself), only the
  /// in-process ports: one data client at most, not taking its own frames.
  bool FramesReachOnlyPorts() const;
  /// Runahead (docs/virtual-time.md): a frame from the port that its recipients get at the
  /// virtual CLOCK_MONOTONIC instant `instant_ns` (not before the frames prepared before it),
  /// routed as SendLocal's would be once everything sent before is routed, and put in each
  /// recipient's ring past what it sees (ucan::RingHeader::rx_prepared_tail). False, with
  /// nothing put, when a recipient cannot take it ahead (no rings of its own doorbell, its ring
  /// full): the caller prepares nothing after it. Call with no frame of the port pending.
  bool PrepareLocal(int port, const CanFrame& frame, std::int64_t instant_ns);
  /// After the firmware gave the clock back: the frames it published are delivered (counted as
  /// routed frames), the rest are dropped, unseen. Returns the number delivered.
  std::uint64_t SettlePrepared();

  /// Grows with everything that can wake a program blocked on a broker socket: writes to a
  /// client (frames, doorbells, replies), a connection accepted (its request answered in the
  /// same pass when it came with the connection, else by a later one), a client dropped.
  /// Equal before and after a Pump(): that pass woke no client.
  std::uint64_t client_progress() const;
  /// Who the passes since the last call woke (the same writes client_progress counts): the data
  /// clients written to (frames, doorbells), by the id their kOpen Reply gave them, and whether
  /// anything else was (a reply, a connection accepted or refused, a client dropped, or more
  /// clients than it keeps by id: then `ids` is empty).
  void TakeWokenClients(UcanWokenClients* out);
  /// The receive timestamps' clock (ns; default CLOCK_REALTIME), e.g. a run's virtual clock.
  /// Set it before traffic, or from the thread that pumps.
  void SetReceiveClock(std::function<std::int64_t()> clock_ns);

  const std::string& runtime_dir() const noexcept;
  std::string socket_path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// True when `name` is acceptable as a bus name (see AddBus).
bool IsValidUcanBusName(const std::string& name) noexcept;

// Client side of the broker's control requests (used by `wheelhil bus`). Each opens one
// connection to the broker serving `runtime_dir`. No broker there: errc::connection_refused or
// errc::no_such_file_or_directory; an unknown bus: errc::no_such_device; bad name:
// errc::invalid_argument. Never throw.
std::error_code UcanAddBus(const std::string& runtime_dir, const std::string& name,
                           int* ifindex) noexcept;
std::error_code UcanRemoveBus(const std::string& runtime_dir, const std::string& name) noexcept;
std::error_code UcanListBuses(const std::string& runtime_dir,
                              std::vector<UcanBusStats>* out) noexcept;
std::error_code UcanShutdown(const std::string& runtime_dir) noexcept;

}  // namespace wheelhil::bus
