// Cell YAML (io/cell_yaml.hpp): parse (schema rcal.cell/1). BuildCell is left out: it opens the
// robot file the input names, and a fuzzer must not choose which files are read.
#include <cstdint>

#include "fuzz_common.hpp"
#include "rcal/io/cell_yaml.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = rcal::fuzz::Text(data, size);
  rcal::fuzz::Refusing([&] {
    const rcal::io::CellSpec spec = rcal::io::ParseCellYaml(text, "fuzz.yaml");
    (void)spec.measures_orientation();
  });
  return 0;
}
