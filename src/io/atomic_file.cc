#include "stiffsim/io/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace stiffsim {

void commit_temporary(const std::string& temp, const std::string& path) {
  std::error_code error;
  std::filesystem::rename(temp, path, error);
  if (error) {
    std::remove(temp.c_str());
    throw std::runtime_error(path + ": cannot rename from " + temp + " (" + error.message() + ")");
  }
}

void close_and_commit(std::FILE* file, bool written, const std::string& temp,
                      const std::string& path) {
  // fclose flushes: a full disk shows here at the latest.
  const bool closed = std::fclose(file) == 0;
  if (!written || !closed) {
    const std::string why = std::strerror(errno);
    std::remove(temp.c_str());
    throw std::runtime_error(temp + ": write failed (" + why + ")");
  }
  commit_temporary(temp, path);
}

void write_file_atomically(const std::string& path, const std::string& text) {
  const std::string temp = path + ".tmp";
  std::FILE* file = std::fopen(temp.c_str(), "wb");
  if (file == nullptr) {
    throw std::runtime_error(temp + ": cannot create (" + std::strerror(errno) + ")");
  }
  const bool written = std::fwrite(text.data(), 1, text.size(), file) == text.size();
  close_and_commit(file, written, temp, path);
}

}  // namespace stiffsim
