#include "emulator/devices/checksum_yaml.h"

#include <fmt/format.h>

namespace wheelhil::emulator {

using bus::yaml::FieldReader;

const std::set<std::string>& ChecksumSpecKeys() {
  static const std::set<std::string> keys{"type",  "data_id",    "data_id_mode", "data_id_list",
                                          "width", "poly",       "init",         "reflect_in",
                                          "reflect_out", "xor_out"};
  return keys;
}

ChecksumSpec ReadChecksumSpec(const FieldReader& r, const YAML::Node& n, const std::string& field) {
  ChecksumSpec spec;
  const std::string type = r.String(n, "type", field, std::nullopt);
  const auto kind = ParseChecksumKind(type);
  if (!kind) {
    r.FailKey(n, "type", field + ".type",
              fmt::format("'{}' is not one of {}", type, ChecksumKindNames()));
  }
  spec.kind = *kind;
  const bool p11 = spec.kind == ChecksumKind::kE2eP11;
  const bool p22 = spec.kind == ChecksumKind::kE2eP22;
  auto only = [&](const char* key, bool allowed, const char* for_what) {
    if (!allowed && FieldReader::Present(FieldReader::Get(n, key))) {
      r.FailKey(n, key, FieldReader::Join(field, key), fmt::format("is for {} only", for_what));
    }
  };
  only("data_id", p11, "e2e_p11");
  only("data_id_mode", p11, "e2e_p11");
  only("data_id_list", p22, "e2e_p22");
  const bool custom = spec.kind == ChecksumKind::kCrcCustom;
  for (const char* key : {"width", "poly", "init", "reflect_in", "reflect_out", "xor_out"}) {
    only(key, custom, "crc");
  }
  if (custom) {
    CrcParams& c = spec.crc;
    c.width = static_cast<int>(r.Integer(n, "width", field, 1, 32));
    const long long max = (1LL << c.width) - 1;
    c.poly = static_cast<std::uint32_t>(r.Integer(n, "poly", field, 1, max));
    c.init = static_cast<std::uint32_t>(r.Integer(n, "init", field, 0, max, 0));
    c.reflect_in = r.Bool(n, "reflect_in", field, false);
    c.reflect_out = r.Bool(n, "reflect_out", field, false);
    c.xor_out = static_cast<std::uint32_t>(r.Integer(n, "xor_out", field, 0, max, 0));
  }
  if (p11) {
    spec.data_id = static_cast<std::uint16_t>(r.Integer(n, "data_id", field, 0, 0xFFFF));
    const std::string mode = r.String(n, "data_id_mode", field, std::string("both"));
    if (mode != "both" && mode != "nibble") {
      r.FailKey(n, "data_id_mode", field + ".data_id_mode",
                fmt::format("'{}' is not both or nibble", mode));
    }
    spec.data_id_nibble = mode == "nibble";
  }
  if (p22) {
    const YAML::Node list = FieldReader::Get(n, "data_id_list");
    if (!list.IsSequence() || list.size() != 16) {
      r.FailKey(n, "data_id_list", field + ".data_id_list",
                "must list 16 bytes (the data id of each counter value)");
    }
    for (std::size_t i = 0; i < 16; ++i) {
      spec.data_id_list[i] = static_cast<std::uint8_t>(
          r.ToInteger(list[i], fmt::format("{}.data_id_list[{}]", field, i), 0, 255));
    }
  }
  return spec;
}

}  // namespace wheelhil::emulator
