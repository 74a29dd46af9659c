// The reference firmware's frame handling (firmware_stub/fw_app.h): any frames, at any times,
// into the app built from each shipped firmware config. Input: [config] then records
// [dt_us:2][id:4][len:1][data:8] (id bit 31: extended, bit 30: RTR); every record is one frame
// arriving dt_us after the previous, with the app's timed work run as due.
#include <cstring>
#include <memory>
#include <vector>

#include "firmware_stub/drive_protocol.h"
#include "firmware_stub/fw_app.h"
#include "firmware_stub/fw_config.h"
#include "firmware_stub/fw_protocol.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace wheelhil;

struct Firmware {
  fw::FwConfig config;
  std::unique_ptr<fw::FwProtocol> protocol;
  std::unique_ptr<fw::DriveProtocol> drives;
};

std::vector<Firmware> LoadFirmwares() {
  const std::string src = WHEELHIL_SOURCE_DIR;
  std::vector<Firmware> out;
  for (const char* name : {"paper000_diff_drive.yaml", "paper001_closed_loop.yaml",
                           "paper002_orthogonal_omni.yaml", "paper001_follower_omni.yaml"}) {
    Firmware f;
    f.config = fw::LoadFwConfig(src + "/scenarios/firmware/" + name);
    std::vector<int> ids;
    for (const auto& n : f.config.encoder_nodes()) ids.push_back(n.node_id);
    const std::string dbc = src + "/bus/dbc";
    f.protocol = std::make_unique<fw::FwProtocol>(fw::FwProtocol::LoadDir(
        dbc, ids, f.config.imu.enabled ? f.config.imu.yaw_frame_id : 0,
        f.config.accel.enabled ? f.config.accel.frame_id : 0));
    if (f.config.drives.enabled) {
      std::vector<int> drive_ids;
      for (const auto& n : f.config.drives.nodes) drive_ids.push_back(n.node_id);
      f.drives = std::make_unique<fw::DriveProtocol>(fw::DriveProtocol::LoadDir(dbc, drive_ids));
    }
    out.push_back(std::move(f));
  }
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::vector<Firmware> firmwares = LoadFirmwares();
  if (size < 1) return 0;
  const Firmware& f = firmwares[data[0] % firmwares.size()];
  fw::FwApp app(f.config, *f.protocol, f.drives.get());
  std::vector<bus::CanFrame> out;
  std::int64_t t_ns = 0;
  app.Start(t_ns, out);
  constexpr std::size_t kRecord = 15;
  for (std::size_t i = 1; i + kRecord <= size; i += kRecord) {
    const std::uint8_t* r = data + i;
    t_ns += (std::int64_t{r[0]} << 8 | r[1]) * 1000;
    std::uint32_t id = 0;
    std::memcpy(&id, r + 2, sizeof(id));
    bus::CanFrame frame;
    frame.extended = (id >> 31) & 1;
    frame.rtr = (id >> 30) & 1;
    frame.id = id & (frame.extended ? bus::CanFrame::kMaxExtendedId : bus::CanFrame::kMaxStandardId);
    frame.len = static_cast<std::uint8_t>(r[6] % (bus::CanFrame::kMaxClassicLen + 1));
    std::memcpy(frame.data.data(), r + 7, bus::CanFrame::kMaxClassicLen);
    // Timed work due before the frame, then the frame (as the firmware's loop does).
    while (app.NextEventNs() <= t_ns) {
      const std::int64_t due = app.NextEventNs();
      app.Poll(due, out);
      if (app.NextEventNs() <= due) break;  // nothing moved: do not spin
    }
    app.OnFrameArrived(frame, t_ns, out);
    out.clear();
  }
  return 0;
}
