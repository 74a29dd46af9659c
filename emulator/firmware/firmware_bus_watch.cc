#include "emulator/firmware/firmware_bus_watch.h"

#include <utility>

#include "bus/canopen.h"
#include "bus/dbc_codec.h"

namespace wheelhil::emulator::firmware {

namespace co = bus::canopen;

namespace {

constexpr std::uint32_t kFwStatusId = 0x686;

std::vector<const bus::DbcSignal*> SignalsNamed(const bus::DbcMessage* msg, const char* name) {
  std::vector<const bus::DbcSignal*> out;
  if (msg == nullptr) return out;
  for (const auto& sg : msg->signals) {
    if (sg.name == name) out.push_back(&sg);
  }
  return out;
}

}  // namespace

FirmwareBusWatch::FirmwareBusWatch(std::shared_ptr<const bus::DbcDatabase> firmware_dbc,
                                   const sim::BusHub& hub, sim::RunContext& run)
    : dbc_(std::move(firmware_dbc)), hub_(hub), run_(run) {
  status_msg_ = dbc_->FindMessage(kFwStatusId, false);
  status_state_ = SignalsNamed(status_msg_, "Status_State");
}

void FirmwareBusWatch::OnEmulatorFrame(const WireFrame& w, int /*device*/) {
  if (w.frame.extended) return;
  const std::uint32_t id = w.frame.id;
  // Boot-ups and SDO answers: the firmware reacts to each.
  if ((co::IsErrorControl(id) && w.frame.len == 1 && w.frame.data[0] == co::nmt_state::kBootUp) ||
      co::IsSdoResponse(id)) {
    awaiting_nodes_.insert(static_cast<int>(co::NodeOf(id)));
  }
}

void FirmwareBusWatch::OnFirmwareFrame(const bus::CanFrame& f) {
  if (f.extended) return;
  // Reactions the start-up waits for: SDO requests and NMT commands.
  if (co::IsSdoRequest(f.id)) awaiting_nodes_.erase(static_cast<int>(co::NodeOf(f.id)));
  if (f.id == co::kNmtCobId && f.len >= 2) {
    if (f.data[1] == 0) {
      awaiting_nodes_.clear();
    } else {
      awaiting_nodes_.erase(f.data[1]);
    }
  }
  if (status_msg_ == nullptr || f.id != kFwStatusId) return;
  auto get = [&](const std::vector<const bus::DbcSignal*>& sigs) {
    double value = 0.0;
    for (const bus::DbcSignal* sig : sigs) {
      if (bus::DecodeSignalIfPresent(*status_msg_, *sig, f, &value)) return value;
    }
    return 0.0;
  };
  const int state = static_cast<int>(get(status_state_));
  if (state != last_state_) {
    last_state_ = state;
    const double t = static_cast<double>(hub_.now_ns()) * 1e-9 - run_.motion0_s;
    run_.events.push_back(
        nlohmann::json{{"t_s", t}, {"event", "firmware_state"}, {"state", state}});
  }
}

}  // namespace wheelhil::emulator::firmware
