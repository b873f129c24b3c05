#include "stiffsim/io/trajectory_writer.h"

#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/io/atomic_file.h"

namespace stiffsim {

void append_number(double value, std::string* out) {
  // std::to_chars without a precision gives the shortest representation that
  // round-trips, which %.17g does not (it prints 0.1 as 0.10000000000000001).
  char text[32];
  const auto result = std::to_chars(text, text + sizeof(text), value);
  out->append(text, result.ptr);
}

// Header fields never need quoting: component names are restricted to
// letters, digits, '_' and '-' by the scene loader, and generated names use
// only '/', so a ',' here would be a bug upstream rather than user input.
std::vector<std::string> trajectory_columns(const System& system) {
  const Dimensions d = system.dimensions();
  const std::vector<std::string> q = system.position_names();
  const std::vector<std::string> v = system.velocity_names();
  const std::vector<std::string> z = system.misc_names();
  if (static_cast<int>(q.size()) != d.nq || static_cast<int>(v.size()) != d.nv ||
      static_cast<int>(z.size()) != d.nz) {
    throw std::logic_error("system '" + system.name() +
                           "' reports column names that do not match its dimensions");
  }
  std::vector<std::string> columns{"t"};
  for (const std::string& name : q) columns.push_back("q:" + name);
  for (const std::string& name : v) columns.push_back("v:" + name);
  for (const std::string& name : z) columns.push_back("z:" + name);
  return columns;
}

TrajectoryWriter::TrajectoryWriter(const std::string& path, const System& system)
    : path_(path), temp_path_(path + ".tmp") {
  const std::vector<std::string> columns = trajectory_columns(system);
  columns_ = static_cast<long>(columns.size()) - 1;
  file_ = std::fopen(temp_path_.c_str(), "wb");
  if (file_ == nullptr) {
    throw InputError(path_ + ": cannot create the trajectory file (" + std::strerror(errno) + ")");
  }
  for (size_t i = 0; i < columns.size(); ++i) {
    if (i > 0) buffer_.push_back(',');
    buffer_.append(columns[i]);
  }
  buffer_.push_back('\n');
  flush_buffer();
}

TrajectoryWriter::~TrajectoryWriter() {
  if (file_ != nullptr) {
    std::fclose(file_);
    std::remove(temp_path_.c_str());
  }
}

void TrajectoryWriter::flush_buffer() {
  if (std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size()) {
    throw std::runtime_error(temp_path_ + ": write failed (" + std::strerror(errno) + ")");
  }
  buffer_.clear();
}

void TrajectoryWriter::write(double t, const Eigen::VectorXd& x) {
  if (file_ == nullptr) throw std::logic_error("TrajectoryWriter::write after finish");
  if (x.size() != columns_) {
    throw std::logic_error("TrajectoryWriter::write: state of size " + std::to_string(x.size()) +
                           ", expected " + std::to_string(columns_));
  }
  append_number(t, &buffer_);
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    buffer_.push_back(',');
    append_number(x[i], &buffer_);
  }
  buffer_.push_back('\n');
  flush_buffer();
  ++rows_;
}

void TrajectoryWriter::close_and_rename() {
  std::FILE* file = file_;
  file_ = nullptr;
  close_and_commit(file, true, temp_path_, path_);
}

void TrajectoryWriter::finish() {
  if (file_ == nullptr) throw std::logic_error("TrajectoryWriter::finish called twice");
  close_and_rename();
}

void TrajectoryWriter::finish_incomplete(const std::string& reason) {
  if (file_ == nullptr) throw std::logic_error("TrajectoryWriter::finish called twice");
  // One comment line: a multi-line reason would break the CSV.
  std::string line = reason;
  for (char& c : line) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  buffer_ = "# stopped early: " + line + "\n";
  flush_buffer();
  close_and_rename();
}

}  // namespace stiffsim
