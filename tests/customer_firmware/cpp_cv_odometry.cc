// A differential-drive odometry firmware written as a customer would write it in C++, knowing
// nothing of wheelhil: plain SocketCAN, a std::thread that blocks in read() and hands frames
// to the control loop under a mutex, and a control loop paced by
// std::condition_variable::wait_until on std::chrono::steady_clock. It is the CANopen master of
// two CiA 406 encoders (boot-up, SDO 0x1800:02 = 1, NMT start, SYNC every period) and publishes
// its pose in its own frames:
//   0x3B0 (8 bytes): x, y   int32 little endian, 0.1 mm
//   0x3B1 (8 bytes): theta  int32 little endian, microradians; cycle uint32
// Usage: cpp_cv_odometry --can IFACE [--left ID] [--right ID] [--cpr N] [--radius M]
//                        [--track M] [--period-ms N]
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cerrno>
#include <cstring>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) { g_stop = true; }

class Can {
 public:
  explicit Can(const std::string& iface) {
    fd_ = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    ifreq ifr{};
    std::strncpy(ifr.ifr_name, iface.c_str(), IFNAMSIZ - 1);
    if (fd_ < 0 || ::ioctl(fd_, SIOCGIFINDEX, &ifr) < 0) {
      throw std::runtime_error(iface + ": " + std::strerror(errno));
    }
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) < 0) {
      throw std::runtime_error("bind " + iface + ": " + std::strerror(errno));
    }
  }
  bool Read(can_frame& f) { return ::read(fd_, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f)); }
  void Send(std::uint32_t id, const std::uint8_t* data, std::uint8_t len) {
    can_frame f{};
    f.can_id = id;
    f.can_dlc = len;
    if (len > 0) std::memcpy(f.data, data, len);
    [[maybe_unused]] const ssize_t n = ::write(fd_, &f, sizeof(f));
  }

 private:
  int fd_ = -1;
};

void PutI32(std::uint8_t* p, std::int32_t v) {
  const auto u = static_cast<std::uint32_t>(v);
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(u >> (8 * i));
}

}  // namespace

int main(int argc, char** argv) {
  std::string iface;
  std::array<int, 2> ids{1, 2};
  int cpr = 2000, period_ms = 10;
  double radius = 0.075, track = 0.32;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--can") iface = v;
    if (k == "--left") ids[0] = std::stoi(v);
    if (k == "--right") ids[1] = std::stoi(v);
    if (k == "--cpr") cpr = std::stoi(v);
    if (k == "--radius") radius = std::stod(v);
    if (k == "--track") track = std::stod(v);
    if (k == "--period-ms") period_ms = std::stoi(v);
  }
  std::signal(SIGTERM, OnSignal);
  Can can(iface);

  std::mutex mu;
  std::condition_variable cv;
  std::deque<can_frame> inbox;
  std::thread reader([&] {
    can_frame f;
    while (!g_stop && can.Read(f)) {
      std::lock_guard lk(mu);
      inbox.push_back(f);
      cv.notify_one();
    }
  });
  reader.detach();

  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::milliseconds(period_ms);
  auto next_tick = Clock::now() + period;
  const auto boot_deadline = Clock::now() + std::chrono::seconds(1);
  std::array<bool, 2> booted{}, configured{}, have{};
  std::array<std::uint32_t, 2> pos{}, last{};
  bool have_last = false, started = false, sdo_sent = false;
  double x = 0, y = 0, theta = 0;
  std::uint32_t cycle = 0;
  std::unique_lock lk(mu);
  while (!g_stop) {
    // The control loop sleeps until its next tick; frames wake it early to be taken in.
    cv.wait_until(lk, next_tick, [&] { return !inbox.empty() || g_stop; });
    while (!inbox.empty()) {
      const can_frame f = inbox.front();
      inbox.pop_front();
      for (int i = 0; i < 2; ++i) {
        const auto id = static_cast<std::uint32_t>(ids[i]);
        if (f.can_id == 0x700 + id && f.can_dlc == 1 && f.data[0] == 0) booted[i] = true;
        if (f.can_id == 0x580 + id && f.data[0] == 0x60 && f.data[1] == 0x00 && f.data[2] == 0x18) {
          configured[i] = true;
        }
        if (f.can_id == 0x180 + id && f.can_dlc >= 4) {
          pos[i] = std::uint32_t{f.data[0]} | std::uint32_t{f.data[1]} << 8 |
                   std::uint32_t{f.data[2]} << 16 | std::uint32_t{f.data[3]} << 24;
          have[i] = true;
        }
      }
    }
    if (Clock::now() < next_tick) continue;
    next_tick += period;
    if (!sdo_sent && ((booted[0] && booted[1]) || Clock::now() > boot_deadline)) {
      for (int i = 0; i < 2; ++i) {
        const std::uint8_t download[8] = {0x2F, 0x00, 0x18, 0x02, 1, 0, 0, 0};
        can.Send(0x600 + static_cast<std::uint32_t>(ids[i]), download, 8);
      }
      sdo_sent = true;
      continue;
    }
    if (sdo_sent && !started && configured[0] && configured[1]) {
      const std::uint8_t start[2] = {0x01, 0x00};
      can.Send(0x000, start, 2);
      started = true;
      continue;
    }
    if (!started) continue;
    can.Send(0x080, nullptr, 0);
    if (have[0] && have[1]) {
      if (have_last) {
        const double k = 2.0 * M_PI * radius / cpr;
        const double dl = static_cast<std::int32_t>(pos[0] - last[0]) * k;
        const double dr = static_cast<std::int32_t>(pos[1] - last[1]) * k;
        const double ds = 0.5 * (dl + dr), dth = (dr - dl) / track;
        x += ds * std::cos(theta + 0.5 * dth);
        y += ds * std::sin(theta + 0.5 * dth);
        theta += dth;
      }
      last = pos;
      have_last = true;
    }
    std::uint8_t d[8];
    PutI32(d, static_cast<std::int32_t>(std::lround(x * 1e4)));
    PutI32(d + 4, static_cast<std::int32_t>(std::lround(y * 1e4)));
    can.Send(0x3B0, d, 8);
    PutI32(d, static_cast<std::int32_t>(std::lround(theta * 1e6)));
    PutI32(d + 4, static_cast<std::int32_t>(cycle++));
    can.Send(0x3B1, d, 8);
  }
  return 0;
}
