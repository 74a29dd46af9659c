#include "emulator/scoring/estimate_decoder.h"

#include <algorithm>
#include <cmath>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator::scoring {

namespace {

std::uint64_t Key(std::uint32_t id, bool extended) {
  return (static_cast<std::uint64_t>(extended) << 32) | id;
}

// The signal's SI value in the frame, or nullopt when the frame does not carry it.
std::optional<double> Value(const bus::DbcMessage& msg, const ResolvedSignal& s,
                            const bus::CanFrame& f) {
  double v = 0.0;
  if (!bus::DecodeSignalIfPresent(msg, *s.signal, f, &v)) return std::nullopt;
  return s.to_si.ToSi(v);
}

}  // namespace

EstimateDecoder::EstimateDecoder(OutputBinding binding) : binding_(std::move(binding)) {
  for (const ResolvedStream& s : binding_.streams()) {
    StreamState st;
    st.stream = &s;
    st.checks = &checks_[s.spec->name];
    by_id_[Key(s.message->id, s.message->extended)].push_back(st);
    if (s.spec->kind == OutputKind::kPose && s.values[2].signal == nullptr) {
      position_only_.insert(s.spec->name);
    }
  }
}

void EstimateDecoder::OnSync(double t_s) {
  sync_times_.push_back(t_s);
}

void EstimateDecoder::OnFrame(const bus::CanFrame& f, double t_s) {
  const auto it = by_id_.find(Key(f.id, f.extended));
  if (it == by_id_.end() || f.rtr) return;
  for (StreamState& st : it->second) {
    Check(st, f, t_s);
    int cycle = static_cast<int>(sync_times_.size()) - 1;
    if (const auto t = SampleTime(st, f, t_s, cycle)) Record(st, f, *t, cycle);
  }
}

void EstimateDecoder::Check(StreamState& st, const bus::CanFrame& f, double t_s) {
  const ResolvedStream& s = *st.stream;
  FrameChecks& c = *st.checks;
  ++c.frames;
  if (f.len != s.message->length) ++c.dlc_errors;
  if (st.last_arrival_s) {
    const double gap = t_s - *st.last_arrival_s;
    c.min_interval_s = c.intervals == 0 ? gap : std::min(c.min_interval_s, gap);
    c.max_interval_s = c.intervals == 0 ? gap : std::max(c.max_interval_s, gap);
    c.sum_interval_s += gap;
    ++c.intervals;
    if (s.expected_cycle_s) {
      const double tol = *s.expected_cycle_s * s.spec->cycle_tolerance;
      if (gap < *s.expected_cycle_s - tol || gap > *s.expected_cycle_s + tol) {
        ++c.cycle_violations;
      }
    }
  }
  st.last_arrival_s = t_s;
  const std::span<const std::uint8_t> payload(f.data.data(), f.len);
  if (s.counter.signal != nullptr) {
    std::uint64_t raw = 0;
    if (bus::ExtractRaw(*s.counter.signal, payload, raw)) {
      const auto m = static_cast<std::int64_t>(s.counter_modulo);
      if (st.last_counter) {
        const std::int64_t expected =
            ((static_cast<std::int64_t>(*st.last_counter) + s.spec->counter_step) % m + m) % m;
        if (static_cast<std::int64_t>(raw) != expected) ++c.counter_errors;
      }
      st.last_counter = raw;
    } else {
      ++c.counter_errors;
    }
  }
  if (s.checksum.signal != nullptr) {
    std::uint64_t raw = 0;
    if (!bus::ExtractRaw(*s.checksum.signal, payload, raw) ||
        raw != ComputeChecksum(s.spec->checksum_kind, *s.checksum.signal, payload)) {
      ++c.checksum_errors;
    }
  }
}

std::optional<double> EstimateDecoder::SampleTime(StreamState& st, const bus::CanFrame& f,
                                                  double t_s, int& cycle) const {
  const ResolvedStream& s = *st.stream;
  if (s.cycle.signal != nullptr) {
    const auto v = Value(*s.message, s.cycle, f);
    if (!v) return std::nullopt;
    // The latest SYNC whose number matches the counter (mod its range).
    const auto m = static_cast<std::int64_t>(s.cycle_modulo);
    const auto c = static_cast<std::int64_t>(*v);
    const auto last = static_cast<std::int64_t>(sync_times_.size()) - 1;
    if (last < 0 || c < 0 || c >= m) return std::nullopt;
    const std::int64_t n = last - ((last - c) % m + m) % m;
    if (n < 0) return std::nullopt;
    cycle = static_cast<int>(c);
    const double t = sync_times_[static_cast<std::size_t>(n)];
    if (t < 0) return std::nullopt;  // a cycle of the boot (a firmware that produces SYNC)
    return t;
  }
  if (t_s < 0) return std::nullopt;
  if (s.timestamp.signal != nullptr) {
    const auto stamp = Value(*s.message, s.timestamp, f);
    if (!stamp) return std::nullopt;
    if (!st.first_stamp_s) st.first_stamp_s = *stamp, st.first_arrival_s = t_s;
    return *st.first_arrival_s + (*stamp - *st.first_stamp_s);
  }
  return t_s;
}

void EstimateDecoder::Record(StreamState& st, const bus::CanFrame& f, double t, int cycle) {
  const ResolvedStream& s = *st.stream;
  const std::string& name = s.spec->name;
  double v[6] = {0, 0, 0, 0, 0, 0};
  for (std::size_t i = 0; i < s.values.size(); ++i) {
    if (s.values[i].signal == nullptr) continue;
    const auto value = Value(*s.message, s.values[i], f);
    if (!value) return;
    v[i] = *value;
  }
  switch (s.spec->kind) {
    case OutputKind::kPose: {
      pose_[name].push_back(PoseSample{t, v[0], v[1], v[2]});
      rows_.push_back({t, cycle, name, v[0], v[1], v[2]});
      break;
    }
    case OutputKind::kVelocity: {
      vel_[name].push_back(VelocitySample{t, v[0], v[1], v[2]});
      rows_.push_back({t, cycle, name, v[0], v[1], v[2]});
      break;
    }
    case OutputKind::kSlip: {
      // flags (a wheel bit mask) or detected: either way "some wheel slips" when non-zero.
      detections_[name].push_back({t, (s.values[0].signal != nullptr ? v[0] : v[1]) != 0});
      const bool calibrated = s.values[2].signal == nullptr || v[2] != 0;
      if (s.values[3].signal != nullptr && calibrated) {
        ResidualTrace& r = residuals_[name];
        r.t_s.push_back(t);
        r.residual_rad.push_back(v[3]);
        if (s.values[4].signal != nullptr) {
          r.band_lower_rad.push_back(v[4]);
          r.band_upper_rad.push_back(v[5]);
        }
      }
      break;
    }
  }
}

}  // namespace wheelhil::emulator::scoring
