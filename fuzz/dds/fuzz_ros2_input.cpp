// The ROS 2 input path (issue 14): whatever the drivers' samples hold after Cyclone DDS has
// deserialised them — any joint names and counts, lengths that disagree, NaN, infinities, absurd
// magnitudes, stamps anywhere (nanosec ≥ 1e9, negative, jumping back and forth), any frame ids —
// goes through ros2_input's core exactly as the process feeds it (Ros2Input: the ROS 2 → rcal
// conversions, the time gates, the magnetometer pairing, the reorder buffer, every source's
// clock-offset estimator and the arm's temperature and payload). A crash, a sanitizer report, an
// exception, a sample leaving out of time order, the conditions out of their own time order, or an
// ARM_CONDITIONS report its adapter refuses is a finding.
//
// Input: a sequence of records, each one opcode byte (which driver topic) then the bytes its
// fields are read from; the stream ends when the bytes do.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <variant>

#include "rcal/dds/ros2_convert.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/transport/adapters.hpp"
#include "ros2_input.hpp"

namespace {

using namespace rcal;

class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : p_(data), end_(data + size) {}
  bool empty() const { return p_ >= end_; }
  std::uint8_t U8() { return empty() ? 0 : *p_++; }
  template <typename T>
  T Raw() {
    T v{};
    const std::size_t n = std::min<std::size_t>(sizeof(T), static_cast<std::size_t>(end_ - p_));
    if (n > 0) std::memcpy(&v, p_, n);
    p_ += n;
    return v;
  }
  // Mostly plausible values (so the deeper code is reached), sometimes raw bits (NaN, 1e300).
  double Value(double scale) {
    const std::uint8_t kind = U8();
    if (kind < 200) return scale * (static_cast<double>(Raw<std::int16_t>()) / 32768.0);
    return Raw<double>();
  }

 private:
  const std::uint8_t* p_;
  const std::uint8_t* end_;
};

struct Cell {
  io::BuiltCell cell = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  ros2::Ros2InputSettings settings = ros2::FromCell(cell);
};

const Cell& Demo() {
  static const Cell c;
  return c;
}

// A stamp near the running clock (small steps, sometimes back, sometimes anywhere).
builtin_interfaces_msg_dds__Time_ Stamp(Bytes& b, std::int64_t& clock_us) {
  const std::uint8_t kind = b.U8();
  if (kind < 220) {
    clock_us += static_cast<std::int64_t>(b.U8()) * 500 - 20'000;
  } else if (kind < 250) {
    clock_us += static_cast<std::int64_t>(b.Raw<std::int32_t>());
  } else {
    return {b.Raw<std::int32_t>(), b.Raw<std::uint32_t>()};  // anything, nanosec ≥ 1e9 too
  }
  const std::int64_t sec = clock_us / 1'000'000;
  return {static_cast<std::int32_t>(sec),
          static_cast<std::uint32_t>(std::llabs(clock_us % 1'000'000) * 1000)};
}

void Frame(Bytes& b, std_msgs_msg_dds__Header_& h, const char* usual) {
  h.frame_id = dds_string_dup(b.U8() < 230 ? usual : "other_frame");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const Cell& demo = Demo();
  transport::Health health("ros2_input");
  ros2::Ros2Input in(demo.settings, demo.cell.model, health);
  Bytes b(data, size);
  std::int64_t clock_us = 1'000'000'000;
  std::int64_t last_out = std::numeric_limits<std::int64_t>::min();
  std::int64_t resyncs = 0;
  std::int64_t last_conditions = std::numeric_limits<std::int64_t>::min();
  auto drain = [&](bool flush) {
    // A re-synchronised stream (a restarted driver) starts a new time base.
    if (health.resyncs() != resyncs)
      last_out = last_conditions = std::numeric_limits<std::int64_t>::min();
    resyncs = health.resyncs();
    for (const auto& e : in.Ready(flush)) {
      const std::int64_t u = sensors::Utime(e);
      if (const auto* c = std::get_if<transport::ArmConditions>(&e)) {
        // The conditions: their own stream (one taken later than the reorder delay leaves at its
        // time, behind the samples), strictly in time order, each one its adapter accepts.
        if (u <= last_conditions) {
          std::fprintf(stderr, "conditions out of order: %lld µs after %lld µs\n",
                       static_cast<long long>(u), static_cast<long long>(last_conditions));
          std::abort();
        }
        last_conditions = u;
        std::string error;
        if (!transport::ArmConditionsFromMessage(transport::ToArmConditions(*c), &error)) {
          std::fprintf(stderr, "published a report its adapter refuses: %s\n", error.c_str());
          std::abort();
        }
        continue;
      }
      if (u < last_out) {
        std::fprintf(stderr, "out of order: %lld µs after %lld µs\n", static_cast<long long>(u),
                     static_cast<long long>(last_out));
        std::abort();  // the pipeline needs one time order
      }
      last_out = u;
    }
  };
  const auto& names = demo.cell.ros2_joint_names;
  for (int records = 0; !b.empty() && records < 4000; ++records) {
    // Opcodes 250-252: the arm's temperature, 253-255: its payload (the other bytes keep the
    // meaning they had).
    const std::uint8_t code = b.U8();
    const std::uint8_t op = code >= 253 ? 6 : code >= 250 ? 5 : code % 5;
    if (op == 5) {
      dds::Sample<dds::Temperature> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "arm");
      m.temperature = b.Value(300.0);
      m.variance = b.Value(1.0);
      in.OnTemperature(m);
    } else if (op == 6) {
      dds::Sample<dds::InertiaStamped> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "tool0");
      m.inertia.m = b.Value(2000.0);
      m.inertia.com.x = b.Value(1.0);
      m.inertia.ixx = b.Value(1.0);
      m.inertia.izz = b.Value(1.0);
      in.OnPayload(m);
    } else if (op == 0) {
      dds::Sample<dds::JointState> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "");
      // Up to 12 names: mostly the arm's (in any order, repeated), some unknown.
      const std::uint32_t n = b.U8() % 13;
      const std::uint32_t np = b.U8() < 230 ? n : b.U8() % 13;
      const std::uint32_t nv = b.U8() < 128 ? n : (b.U8() < 200 ? 0 : b.U8() % 13);
      m.name._buffer = n ? static_cast<char**>(dds_alloc(n * sizeof(char*))) : nullptr;
      m.name._length = m.name._maximum = n;
      m.name._release = true;
      for (std::uint32_t i = 0; i < n; ++i) {
        const std::uint8_t k = b.U8();
        m.name._buffer[i] = dds_string_dup(k < 240 ? names[k % names.size()].c_str() : "gripper");
      }
      for (auto [seq, len] : {std::pair{&m.position, np}, std::pair{&m.velocity, nv}}) {
        seq->_buffer = len ? static_cast<double*>(dds_alloc(len * sizeof(double))) : nullptr;
        seq->_length = seq->_maximum = len;
        seq->_release = true;
        for (std::uint32_t i = 0; i < len; ++i) seq->_buffer[i] = b.Value(3.0);
      }
      in.OnJointState(m);
    } else if (op == 1) {
      dds::Sample<dds::Imu> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "imu_link");
      m.angular_velocity = {b.Value(2.0), b.Value(2.0), b.Value(2.0)};
      m.linear_acceleration = {b.Value(12.0), b.Value(12.0), b.Value(12.0)};
      in.OnImu(m);
    } else if (op == 2) {
      dds::Sample<dds::MagneticField> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "imu_link");
      m.magnetic_field = {b.Value(6e-5), b.Value(6e-5), b.Value(6e-5)};
      in.OnMagneticField(m);
    } else if (op == 3) {
      dds::Sample<dds::PointStamped> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "tracker");
      m.point = {b.Value(3.0), b.Value(3.0), b.Value(3.0)};
      in.OnPoint(0, m);
    } else {
      // A PoseStamped on the tracker's PointStamped topic index, and an index beyond the topics.
      dds::Sample<dds::PoseStamped> s;
      auto& m = s.get();
      m.header.stamp = Stamp(b, clock_us);
      Frame(b, m.header, "tracker");
      m.pose.position = {b.Value(3.0), b.Value(3.0), b.Value(3.0)};
      m.pose.orientation.w = 1.0;
      in.OnPose(b.U8() % 3, m);
    }
    if (b.U8() < 64) drain(false);
  }
  drain(true);
  (void)in.ClockMessage(in.joints_utime());
  return 0;
}
