// IMU stream CSV, BROAD layout (io/imu_csv.hpp).
#include <cstdint>

#include "fuzz_common.hpp"
#include "rcal/io/imu_csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = rcal::fuzz::Text(data, size);
  rcal::fuzz::Refusing([&] { (void)rcal::io::ParseImuCsv(text, "fuzz.csv"); });
  return 0;
}
