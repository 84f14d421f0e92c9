// libFuzzer target: the TetGen reader through readTetMesh, from two temporary files (a .node and an
// .ele), so that the whole-file reading (regular files only, the size limit) runs too. The input is
// the .node text, the line "@@ele@@", then the .ele text; without that line it is all .node text
// and the .ele file is empty.
#include "fuzz_support.hpp"

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

#include <unistd.h>

namespace {

/// A folder of this process's own, removed at exit.
struct TempFolder {
  std::filesystem::path path = std::filesystem::temp_directory_path() /
                               ("corofem-fuzz-tetgen-" + std::to_string(static_cast<long>(::getpid())));
  TempFolder() { std::filesystem::create_directories(path); }
  ~TempFolder() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
};

void writeFile(const std::filesystem::path& path, std::string_view text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) corofem::fuzz::violated("cannot write the temporary file " + path.string());
  const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  if (std::fclose(f) != 0 || !ok) corofem::fuzz::violated("cannot write the temporary file " + path.string());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace corofem;
  static const TempFolder folder;
  const std::string expanded = fuzz::expandRuns({reinterpret_cast<const char*>(data), size});
  const std::string_view input(expanded);
  constexpr std::string_view kSeparator = "\n@@ele@@\n";
  const std::size_t split = input.find(kSeparator);
  const std::string_view node = input.substr(0, split);
  const std::string_view ele = split == std::string_view::npos ? std::string_view() : input.substr(split + kSeparator.size());
  writeFile(folder.path / "fuzz.node", node);
  writeFile(folder.path / "fuzz.ele", ele);
  const Result<TetMesh> mesh = readTetMesh((folder.path / "fuzz.node").string());
  if (mesh.isOk()) fuzz::checkTetMesh(mesh.value(), "fuzz.node/.ele");
  else fuzz::checkRefusal(mesh.status(), "fuzz.node/.ele");
  return 0;
}
