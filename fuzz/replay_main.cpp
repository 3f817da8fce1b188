// Replays a fuzz target's corpus without libFuzzer: every regular file under the directories (or
// the files) given on the command line goes through LLVMFuzzerTestOneInput once. Built with any
// compiler, so the corpus, and every input that once crashed a parser, is a test in every build.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {
int Replay(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  // A copy of exactly `size` bytes, so that reading past the input is caught by ASan.
  std::vector<std::uint8_t> data(bytes.begin(), bytes.end());
  LLVMFuzzerTestOneInput(data.empty() ? nullptr : data.data(), data.size());
  return 1;
}
}  // namespace

int main(int argc, char** argv) {
  int n = 0;
  for (int i = 1; i < argc; ++i) {
    const std::filesystem::path p(argv[i]);
    if (std::filesystem::is_directory(p)) {
      for (const auto& e : std::filesystem::recursive_directory_iterator(p))
        if (e.is_regular_file()) n += Replay(e.path());
    } else if (std::filesystem::is_regular_file(p)) {
      n += Replay(p);
    } else {
      std::fprintf(stderr, "replay: %s is neither a file nor a folder\n", argv[i]);
      return 2;
    }
  }
  std::printf("replayed %d inputs\n", n);
  if (n == 0) {
    std::fprintf(stderr, "replay: no input found: the corpus is empty\n");
    return 1;
  }
  return 0;
}
