#include "stiffsim/io/vtk_writer.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/io/atomic_file.h"
#include "stiffsim/io/scene_drawing.h"
#include "stiffsim/io/trajectory_writer.h"

namespace stiffsim {
namespace {

void append_int(long value, std::string* out) { out->append(std::to_string(value)); }

std::string json_string(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') {
      out.push_back('\\');
      out.push_back(c);
    } else if (static_cast<unsigned char>(c) < 0x20) {
      out.push_back(' ');
    } else {
      out.push_back(c);
    }
  }
  return out + "\"";
}

}  // namespace

VtkWriter::VtkWriter(std::string directory, const Scene& scene,
                     const std::vector<std::vector<std::array<int, 3>>>& surfaces)
    : directory_(std::move(directory)),
      scene_name_(scene.name()),
      scene_(scene),
      surfaces_(surfaces) {
  state_size_ = scene.dimensions().nx();
  // The topology never changes: built once from the initial drawing.
  const std::vector<ComponentDrawing> drawing =
      draw_scene(scene_, surfaces_, 0.0, scene.initial_state().x);
  if (drawing.empty()) {
    throw InputError("--vtk: scene '" + scene_name_ + "' has no components to draw");
  }
  std::error_code error;
  std::filesystem::create_directories(directory_, error);
  if (error || !std::filesystem::is_directory(directory_)) {
    throw InputError(directory_ + ": cannot create the VTK directory" +
                     (error ? " (" + error.message() + ")" : std::string()));
  }
  std::string polygons, lines;
  long polygon_count = 0, line_count = 0;
  for (const ComponentDrawing& part : drawing) {
    const long first = point_count_;
    if (!part.triangles.empty()) {
      for (const auto& t : part.triangles) {
        polygons += "3";
        for (int v : t) {
          polygons.push_back(' ');
          append_int(first + v, &polygons);
        }
        polygons.push_back('\n');
        ++polygon_count;
      }
    } else {
      for (const auto& seg : part.segments) {
        lines += "2 ";
        append_int(first + seg[0], &lines);
        lines.push_back(' ');
        append_int(first + seg[1], &lines);
        lines.push_back('\n');
        ++line_count;
      }
    }
    point_count_ += part.points.cols();
  }
  if (polygon_count > 0) {
    topology_ += "POLYGONS " + std::to_string(polygon_count) + " " +
                 std::to_string(4 * polygon_count) + "\n" + polygons;
  }
  if (line_count > 0) {
    topology_ +=
        "LINES " + std::to_string(line_count) + " " + std::to_string(3 * line_count) + "\n" + lines;
  }
}

std::string VtkWriter::frame_path(long index) const {
  char number[32];
  std::snprintf(number, sizeof(number), "_%05ld.vtk", index);
  return (std::filesystem::path(directory_) / (scene_name_ + number)).string();
}

std::string VtkWriter::series_path() const {
  return (std::filesystem::path(directory_) / (scene_name_ + ".vtk.series")).string();
}

void VtkWriter::write_frame(double t, const Eigen::VectorXd& x) {
  if (x.size() != state_size_) {
    throw std::logic_error("VtkWriter::write_frame: state of size " + std::to_string(x.size()) +
                           ", expected " + std::to_string(state_size_));
  }
  std::string& out = buffer_;
  out.clear();
  out += "# vtk DataFile Version 3.0\n";
  out += "stiffsim " + scene_name_ + " t=";
  append_number(t, &out);
  out += "\nASCII\nDATASET POLYDATA\n";
  // TIME as field data lets a single frame carry its time too.
  out += "FIELD FieldData 1\nTIME 1 1 double\n";
  append_number(t, &out);
  out += "\nPOINTS " + std::to_string(point_count_) + " double\n";
  const std::vector<ComponentDrawing> drawing = draw_scene(scene_, surfaces_, t, x);
  auto append_columns = [&out](const Eigen::Matrix3Xd& m) {
    for (Eigen::Index n = 0; n < m.cols(); ++n) {
      for (int k = 0; k < 3; ++k) {
        if (k > 0) out.push_back(' ');
        append_number(m(k, n), &out);
      }
      out.push_back('\n');
    }
  };
  for (const ComponentDrawing& part : drawing) append_columns(part.points);
  out += topology_;
  out += "POINT_DATA " + std::to_string(point_count_) + "\nVECTORS velocity double\n";
  for (const ComponentDrawing& part : drawing) append_columns(part.velocities);
  out += "SCALARS component int 1\nLOOKUP_TABLE default\n";
  for (const ComponentDrawing& part : drawing) {
    for (Eigen::Index n = 0; n < part.points.cols(); ++n) {
      append_int(part.component, &out);
      out.push_back('\n');
    }
  }
  write_file_atomically(frame_path(frames()), out);
  times_.push_back(t);
}

void VtkWriter::write_series(const std::string& reason) {
  std::string out = "{\n  \"file-series-version\": \"1.0\",\n";
  if (!reason.empty()) out += "  \"stopped_early\": " + json_string(reason) + ",\n";
  out += "  \"files\": [";
  for (size_t i = 0; i < times_.size(); ++i) {
    out += i == 0 ? "\n" : ",\n";
    out +=
        "    {\"name\": " +
        json_string(std::filesystem::path(frame_path(static_cast<long>(i))).filename().string()) +
        ", \"time\": ";
    append_number(times_[i], &out);
    out += "}";
  }
  out += "\n  ]\n}\n";
  write_file_atomically(series_path(), out);
}

void VtkWriter::finish() { write_series(""); }

void VtkWriter::finish_incomplete(const std::string& reason) {
  write_series(reason.empty() ? "unknown reason" : reason);
}

}  // namespace stiffsim
