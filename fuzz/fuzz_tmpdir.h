#pragma once

#include <cctype>
// Shared by the fuzz targets: the loaders under test take a path, so each
// input is written to a file in a private temporary directory first.

#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

namespace stiffsim_fuzz {

// One directory per fuzzer process (libFuzzer's -jobs/-fork run several side
// by side), holding a link "meshes" to models/meshes so that the seed scenes'
// relative mesh paths resolve and the fuzzer reaches the mesh component code.
inline const std::filesystem::path& work_dir() {
  static const std::filesystem::path dir = [] {
    std::string tmpl = (std::filesystem::temp_directory_path() / "stiffsim-fuzz-XXXXXX").string();
    if (mkdtemp(tmpl.data()) == nullptr) {
      std::perror("mkdtemp");
      std::abort();
    }
    std::filesystem::path d(tmpl);
    std::error_code ignored;
    std::filesystem::create_directory_symlink(
        std::filesystem::path(STIFFSIM_SOURCE_DIR) / "models" / "meshes", d / "meshes", ignored);
    // Not removed at exit on purpose: a crash leaves the last input behind
    // (scripts/fuzz points TMPDIR into build-fuzz/ and empties it per run).
    return d;
  }();
  return dir;
}

inline std::string write_input(const std::string& name, const uint8_t* data, size_t size) {
  const std::filesystem::path file = work_dir() / name;
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) std::abort();  // a full /tmp would otherwise look like loader bugs
  return file.string();
}

// Scenes may name a mesh by absolute path. Reading a device or kernel file
// (/dev/zero, /dev/stdin) never ends or blocks; that is the operating system
// doing what the user asked, not a loader bug, so such inputs are skipped.
inline bool names_special_file(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  for (const char* prefix : {"/dev", "/proc", "/sys"}) {
    if (text.find(prefix) != std::string::npos) return true;
  }
  return false;
}

// A scene's loading work grows with the sizes it asks for (a 666 x 666 cloth
// is half a million nodes and millions of springs, legal up to the loader's
// limit of 10^7 nodes): such inputs are slow by design, not hangs, and the
// limits themselves are covered by the bad-input corpus. Inputs with an
// integer above 200 outside a floating-point literal are skipped, so that a
// timeout still means a loop that does not end.
inline bool asks_for_a_large_scene(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  for (size_t i = 0; i < text.size();) {
    if (!std::isdigit(static_cast<unsigned char>(text[i]))) {
      ++i;
      continue;
    }
    size_t j = i;
    while (j < text.size() && std::isdigit(static_cast<unsigned char>(text[j]))) ++j;
    const bool in_float = (i > 0 && (text[i - 1] == '.' || text[i - 1] == 'e' || text[i - 1] == 'E')) ||
                          (j < text.size() && (text[j] == '.' || text[j] == 'e' || text[j] == 'E'));
    if (!in_float && (j - i > 3 || std::stol(text.substr(i, j - i)) > 200)) return true;
    i = j;
  }
  return false;
}

}  // namespace stiffsim_fuzz
