// ros2_input: a cell's ROS 2 drivers into the pipeline, over Cyclone DDS with the ROS 2 wire types
// (no ROS installation). The cell file's `ros2:` section names the topics; rcal::ros2::Ros2Input
// (ros2_input.hpp) maps joints by name, moves every driver's stamps to the arm's clock and checks
// every sample.
//
// Subscribes on DDS (ROS 2 topic /x is DDS topic rt/x; the sensor-data QoS of ROS 2: best effort,
// volatile, so any driver's writer matches):
//   rt<joint_states>  sensor_msgs::msg::dds_::JointState_
//   rt<imu>           sensor_msgs::msg::dds_::Imu_             (cells with an IMU)
//   rt<mag>           sensor_msgs::msg::dds_::MagneticField_   (optional)
//   rt<position i>    geometry_msgs::msg::dds_::PointStamped_ or PoseStamped_, one per marker
//   rt<temperature>   sensor_msgs::msg::dds_::Temperature_ (optional: the arm's temperature)
//   rt<payload>       geometry_msgs::msg::dds_::InertiaStamped_ (optional: what the arm carries)
// Publishes on LCM (the cell's channels): JOINTS, IMU, POSITION as sensor_acquisition does, so the
// rest of the pipeline is unchanged; ARM_CONDITIONS for each temperature or payload report (in
// time order with the samples, its driver's clock moved to the joints': ros2_input.hpp);
// CLOCK_OFFSET (every source's offset, σ and state) at 1 Hz of the joints' time and whenever a
// state changes; HEALTH at 1 Hz, with DDS samples lost or rejected by the readers counted as
// dropped.
//
// Cyclone binds to loopback only (config/cyclonedds-loopback.xml) unless CYCLONEDDS_URI is set.
// Samples whose CDR Cyclone cannot deserialise never reach rcal (Cyclone drops them); everything
// that does is checked (ros2_convert.hpp).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <map>
#include <memory>

#include "rcal/dds/dds_common.hpp"
#include "rcal/dds/ros2_convert.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/services/common.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"
#include "ros2_input.hpp"

namespace {

using namespace rcal;

struct Reader {
  std::string topic;  // the ROS 2 name
  dds_entity_t reader = 0;
  std::function<void(const void*)> on_sample;
  int64_t lost = 0, rejected = 0;  // DDS-level counts
};

// Delivery latency (the driver's write → this process taking the sample; both wall clocks of one
// machine, DDS's source timestamp) in 0.1 ms bins up to 1 s: its median and 99th percentile for
// the log. The reorder buffer adds reorder_delay on top before a sample is published.
class LatencyHistogram {
 public:
  void Add(int64_t ns) {
    const auto bin = std::clamp<int64_t>(ns / 100'000, 0, kBins - 1);
    ++bins_[static_cast<size_t>(bin)];
    ++n_;
  }
  /// The q-quantile [ms] (upper edge of its bin), NaN when empty.
  double QuantileMs(double q) const {
    if (n_ == 0) return std::nan("");
    const auto target = static_cast<int64_t>(std::ceil(q * static_cast<double>(n_)));
    int64_t sum = 0;
    for (size_t i = 0; i < bins_.size(); ++i)
      if ((sum += bins_[i]) >= target) return 0.1 * static_cast<double>(i + 1);
    return 0.1 * kBins;
  }
  int64_t count() const { return n_; }

 private:
  static constexpr int64_t kBins = 10'000;
  std::vector<int64_t> bins_ = std::vector<int64_t>(kBins, 0);
  int64_t n_ = 0;
};

template <typename T>
Reader MakeReader(dds_entity_t participant, const std::string& ros_topic,
                  std::function<void(const T&)> on) {
  // A deep history: a burst between two takes is not overwritten.
  const std::unique_ptr<dds_qos_t, void (*)(dds_qos_t*)> qos(dds::SensorDataQos(256),
                                                             dds_delete_qos);
  const dds_entity_t reader = dds::CreateEndpoint(participant, dds::Descriptor<T>(),
                                                  dds::DdsTopicName(ros_topic), qos.get(), false);
  Reader r;
  r.topic = ros_topic;
  r.reader = reader;
  r.on_sample = [on = std::move(on)](const void* s) { on(*static_cast<const T*>(s)); };
  return r;
}

// Takes everything a reader has (loaned samples), in order. Returns the number taken.
int TakeAll(Reader& r, LatencyHistogram& latency) {
  constexpr int kBatch = 64;
  int total = 0;
  for (;;) {
    void* samples[kBatch] = {nullptr};
    dds_sample_info_t infos[kBatch];
    const dds_return_t n = dds_take(r.reader, samples, infos, kBatch, kBatch);
    if (n <= 0) break;
    const dds_time_t now = dds_time();
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      latency.Add(now - infos[i].source_timestamp);
      r.on_sample(samples[i]);
    }
    dds_return_loan(r.reader, samples, n);
    total += n;
    if (n < kBatch) break;
  }
  // Loss the readers saw (history overrun does not show here: keep-last drops silently, hence the
  // deep history; lost = never received, rejected = resource limits).
  dds_sample_lost_status_t lost;
  if (dds_get_sample_lost_status(r.reader, &lost) == DDS_RETCODE_OK) r.lost = lost.total_count;
  dds_sample_rejected_status_t rejected;
  if (dds_get_sample_rejected_status(r.reader, &rejected) == DDS_RETCODE_OK)
    r.rejected = rejected.total_count;
  return total;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "ros2_input: a cell's ROS 2 drivers (sensor_msgs/JointState, Imu, MagneticField,\n"
      "Temperature, geometry_msgs/PointStamped or PoseStamped) over Cyclone DDS into the\n"
      "pipeline's JOINTS, IMU, POSITION and ARM_CONDITIONS, every driver's stamps moved to the\n"
      "arm's clock (CLOCK_OFFSET).\n"
      "Topics, joint names and frames from the cell file's ros2: section.\n"
      "Cyclone DDS: $CYCLONEDDS_URI, else config/cyclonedds-loopback.xml.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  std::string cell_path, lcm_url, name = "ros2_input";
  int domain = -1;
  app.add_option("--cell", cell_path, "cell file (schema rcal.cell/1) with a ros2: section")
      ->required();
  app.add_option("--dds-domain", domain, "DDS domain id (default: the cell's ros2.domain)");
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  app.add_option("--name", name, "process name in HEALTH")->capture_default_str();
  double reorder_delay = ros2::Ros2InputSettings{}.reorder_delay;
  app.add_option("--reorder-delay", reorder_delay,
                 "[s] samples leave in time order this long after the newest (the spread of the "
                 "drivers' latencies it absorbs)")
      ->check(CLI::Range(0.0, 5.0))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  std::optional<io::BuiltCell> cell;
  std::optional<ros2::Ros2InputSettings> settings;
  try {
    cell = io::LoadCell(services::RepoPath(cell_path));
    settings = ros2::FromCell(*cell);
    settings->reorder_delay = reorder_delay;
  } catch (const std::exception& e) {
    spdlog::error("--cell: {}", e.what());
    return 2;
  }
  if (domain < 0) domain = cell->spec.ros2->domain;

  try {
    services::InstallStopHandlers();
    const std::string uri = dds::EnsureCycloneConfig();
    dds::EntityGuard participant(
        dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr));
    if (participant.get() < 0)
      throw std::runtime_error(std::string("dds_create_participant (CYCLONEDDS_URI ") + uri +
                               "): " + dds_strretcode(participant.get()));
    transport::LcmTransport t(lcm_url);
    transport::Health health(name);
    ros2::Ros2Input input(*settings, cell->model, health);
    const io::CellChannels& ch = cell->spec.channels;

    int64_t published = 0;
    auto publish = [&](const std::vector<sensors::SensorEvent>& events) {
      for (const auto& e : events) {
        bool ok = false;
        if (const auto* imu = std::get_if<transport::ImuSample>(&e))
          ok = t.Publish(ch.imu, transport::ToMessage(*imu));
        else if (const auto* pos = std::get_if<transport::PositionSample>(&e))
          ok = t.Publish(ch.position, transport::ToMessage(*pos));
        else if (const auto* js = std::get_if<joint_state_t>(&e))
          ok = t.Publish(ch.joints, *js);
        else if (const auto* c = std::get_if<transport::ArmConditions>(&e))
          ok = t.Publish(ch.arm_conditions, transport::ToArmConditions(*c));
        if (ok) {
          health.Published();
          ++published;
        } else {
          health.Error("LCM publish failed");
        }
      }
    };

    std::vector<Reader> readers;
    readers.push_back(
        MakeReader<dds::JointState>(participant.get(), settings->joint_topic,
                                    [&](const dds::JointState& m) { input.OnJointState(m); }));
    // The magnetometer first: an IMU sample pairs with the reading nearest in time.
    if (!settings->mag_topic.empty())
      readers.push_back(MakeReader<dds::MagneticField>(
          participant.get(), settings->mag_topic,
          [&](const dds::MagneticField& m) { input.OnMagneticField(m); }));
    if (!settings->imu_topic.empty())
      readers.push_back(MakeReader<dds::Imu>(participant.get(), settings->imu_topic,
                                             [&](const dds::Imu& m) { input.OnImu(m); }));
    // The arm's conditions (temperature, payload): one stream, through the reorder buffer with
    // the samples (ros2_input.hpp).
    if (!settings->temperature_topic.empty())
      readers.push_back(
          MakeReader<dds::Temperature>(participant.get(), settings->temperature_topic,
                                       [&](const dds::Temperature& m) { input.OnTemperature(m); }));
    if (!settings->payload_topic.empty())
      readers.push_back(MakeReader<dds::InertiaStamped>(
          participant.get(), settings->payload_topic,
          [&](const dds::InertiaStamped& m) { input.OnPayload(m); }));
    for (size_t i = 0; i < settings->positions.size(); ++i) {
      const auto& p = settings->positions[i];
      if (p.pose)
        readers.push_back(MakeReader<dds::PoseStamped>(
            participant.get(), p.topic, [&, i](const dds::PoseStamped& m) { input.OnPose(i, m); }));
      else
        readers.push_back(MakeReader<dds::PointStamped>(
            participant.get(), p.topic,
            [&, i](const dds::PointStamped& m) { input.OnPoint(i, m); }));
    }
    const dds_entity_t waitset = dds_create_waitset(participant.get());
    for (const Reader& r : readers) {
      const dds_entity_t cond = dds_create_readcondition(r.reader, DDS_ANY_STATE);
      dds_waitset_attach(waitset, cond, r.reader);
    }

    std::string topics;
    for (const Reader& r : readers) topics += (topics.empty() ? "" : ", ") + r.topic;
    spdlog::info("ros2_input for cell '{}': DDS domain {} ({}) -> LCM {} (CYCLONEDDS_URI {})",
                 cell->spec.name, domain, topics, t.url(), uri);
    health.Tick(0, t, ch.health);  // "up": the readers are in place

    LatencyHistogram latency;
    int64_t logged_rejections = 0;
    std::vector<int8_t> last_states;
    int64_t last_clock_report = 0;
    while (!services::StopRequested()) {
      dds_waitset_wait(waitset, nullptr, 0, DDS_MSECS(100));
      for (Reader& r : readers) TakeAll(r, latency);
      publish(input.Ready());
      int64_t dropped = 0;
      for (const Reader& r : readers) dropped += r.lost + r.rejected;
      health.SetDropped(dropped);
      if (health.rejected() > logged_rejections) {
        spdlog::warn("rejected {} so far; the last: {}", health.rejected(), health.last_error());
        logged_rejections = health.rejected();
      }
      const int64_t now = input.joints_utime();
      // CLOCK_OFFSET: 1 Hz of the joints' time, and at once when a state changes.
      const clock_offset_t clocks = input.ClockMessage(now);
      if (now > 0 && (clocks.state != last_states || now - last_clock_report >= 1'000'000)) {
        if (clocks.state != last_states)
          for (const ros2::ClockStatus& c : input.Clocks())
            spdlog::info("clock {}: state {} offset {:.2f} ms σ {:.2f} ms (resets {})", c.source,
                         static_cast<int>(c.state), 1e3 * c.offset, 1e3 * c.sigma, c.resets);
        t.Publish(ch.clock_offset, clocks);
        last_states = clocks.state;
        last_clock_report = now;
      }
      health.Tick(now, t, ch.health);
      t.HandleTimeout(0);
    }
    publish(input.Ready(true));
    health.Final(t, ch.health);
    for (const ros2::ClockStatus& c : input.Clocks())
      spdlog::info("clock {} at the end: state {} offset {:.2f} ms σ {:.2f} ms (resets {})",
                   c.source, static_cast<int>(c.state), 1e3 * c.offset, 1e3 * c.sigma, c.resets);
    spdlog::info(
        "stopped: {} samples published, {} late (dropped), {} IMU samples with a magnetometer "
        "reading, {} temperature and {} payload reports ({} later than the reorder delay, "
        "published all the same); DDS delivery latency median {:.1f} ms, 99 % {:.1f} ms over {} "
        "samples (+ the reorder delay {:.0f} ms before publishing)",
        published, input.late(), input.mag_paired(), input.temperatures(), input.payloads(),
        input.conditions_late(), latency.QuantileMs(0.5), latency.QuantileMs(0.99), latency.count(),
        1e3 * settings->reorder_delay);
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
