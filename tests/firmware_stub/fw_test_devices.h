#pragma once
/// Test helpers for the firmware program: the protocol bound to the real bus/dbc/ files, and
/// device frames built through the DBC codec (what the emulator's nodes send), so the firmware
/// is driven with CanFrames exactly as on the bus. Test-only; nothing of emulator/ is used.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/candump_log.h"
#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "firmware_stub/fw_protocol.h"

namespace wheelhil::fw::testing {

inline std::string DbcDir() { return std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc"; }

inline bus::CanFrame Frame(const std::string& text) {
  bus::CanFrame f;
  std::string error;
  EXPECT_TRUE(bus::ParseCanUtilsFrame(text, f, &error)) << text << ": " << error;
  return f;
}

inline std::vector<std::string> Strings(const std::vector<bus::CanFrame>& frames) {
  std::vector<std::string> out;
  for (const auto& f : frames) out.push_back(bus::ToCanUtilsString(f));
  return out;
}

/// Builds the frames the devices of the platforms send, through the DBC files.
class Devices {
 public:
  Devices()
      : co_(bus::DbcDatabase::LoadFile(DbcDir() + "/cia406_encoder.dbc")),
        imu_(bus::DbcDatabase::LoadFile(DbcDir() + "/bosch_mm5_10.dbc")),
        acc_(bus::DbcDatabase::LoadFile(DbcDir() + "/wheelhil_accel4.dbc")) {}

  bus::CanFrame Boot(int node) const { return State(node, 0x00); }
  bus::CanFrame State(int node, int state) const {
    return Encode(co_, 0x700 + node, {{"NMT_State", state}});
  }
  bus::CanFrame Tpdo(int node, std::uint32_t position, int speed = 0) const {
    return Encode(co_, 0x180 + node,
                  {{"PositionValue", static_cast<double>(position)}, {"SpeedValue", speed}});
  }
  bus::CanFrame Emcy(int node, int code, int reg) const {
    return Encode(co_, 0x080 + node, {{"EMCY_ErrorCode", code}, {"EMCY_ErrorRegister", reg}});
  }
  /// SDO answer to `request` (an 0x600+id frame): success (0x60) or abort with `abort_code`.
  bus::CanFrame SdoAnswer(const bus::CanFrame& request, std::uint32_t abort_code = 0) const {
    const int node = static_cast<int>(request.id - 0x600);
    const auto* rq = co_.FindMessage(request.id, false);
    const auto v = bus::DecodeMessage(*rq, request);
    return Encode(co_, 0x580 + node,
                  {{"SDO_Command", abort_code ? 0x80 : 0x60},
                   {"SDO_Index", v.at("SDO_Index")},
                   {"SDO_SubIndex", v.at("SDO_SubIndex")},
                   {"SDO_Data", static_cast<double>(abort_code)}});
  }
  bus::CanFrame Yaw(double rate_rad_s) const {
    return Encode(imu_, 0x174, {{"MM5_YawRate", rate_rad_s * 180.0 / M_PI}, {"MM5_AccelY", 0}});
  }
  /// ACC4_Data with counter and the XOR-of-nibbles checksum of wheelhil_accel4.dbc.
  bus::CanFrame Accel(const std::array<double, 4>& a, int counter) const {
    bus::CanFrame f = Encode(acc_, 0x170,
                             {{"ACC4_A1", a[0]},
                              {"ACC4_A2", a[1]},
                              {"ACC4_A3", a[2]},
                              {"ACC4_A4", a[3]},
                              {"ACC4_Counter", counter & 15}});
    std::uint8_t x = f.data[7] & 0x0F;
    for (int i = 0; i < 7; ++i) x ^= (f.data[i] & 0x0F) ^ (f.data[i] >> 4);
    f.data[7] = static_cast<std::uint8_t>((f.data[7] & 0x0F) | (x << 4));
    return f;
  }

  const bus::DbcDatabase& cia406() const { return co_; }

 private:
  static bus::CanFrame Encode(const bus::DbcDatabase& db, std::uint32_t id,
                              const bus::SignalValues& values) {
    const auto* m = db.FindMessage(id, false);
    EXPECT_NE(m, nullptr) << std::hex << id;
    bus::CanFrame f;
    std::string problem;
    EXPECT_TRUE(bus::EncodeMessage(*m, values, f, &problem)) << problem;
    return f;
  }

  bus::DbcDatabase co_, imu_, acc_;
};

}  // namespace wheelhil::fw::testing
