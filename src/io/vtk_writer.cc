#include "stiffsim/io/vtk_writer.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/io/atomic_file.h"
#include "stiffsim/io/trajectory_writer.h"
#include "stiffsim/model/particles.h"

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
    : directory_(std::move(directory)), scene_name_(scene.name()) {
  const Dimensions dims = scene.dimensions();
  state_size_ = dims.nx();
  for (int i = 0; i < scene.component_count(); ++i) {
    const auto* particles = dynamic_cast<const ParticleSystem*>(&scene.component(i));
    if (particles == nullptr) continue;
    parts_.push_back({particles, scene.offsets(i).nq, dims.nq + scene.offsets(i).nv, point_count_});
    point_count_ += particles->node_count();
  }
  if (parts_.empty()) {
    throw InputError("--vtk: scene '" + scene_name_ + "' has no particle components to draw");
  }
  std::error_code error;
  std::filesystem::create_directories(directory_, error);
  if (error || !std::filesystem::is_directory(directory_)) {
    throw InputError(directory_ + ": cannot create the VTK directory" +
                     (error ? " (" + error.message() + ")" : std::string()));
  }

  // The connectivity never changes: build it once.
  std::string polygons, lines;
  long polygon_count = 0, line_count = 0;
  int component = 0;
  for (const Part& part : parts_) {
    const int nodes = part.system->node_count();
    const std::vector<std::array<int, 3>>* triangles = nullptr;
    // Find this part's component index to look up its surface.
    while (&scene.component(component) != part.system) ++component;
    if (component < static_cast<int>(surfaces.size()) && !surfaces[component].empty()) {
      triangles = &surfaces[component];
      for (const auto& t : *triangles) {
        if (t[0] < 0 || t[1] < 0 || t[2] < 0 || t[0] >= nodes || t[1] >= nodes || t[2] >= nodes) {
          triangles = nullptr;  // not this component's numbering: draw springs instead
          break;
        }
      }
    }
    if (triangles != nullptr) {
      for (const auto& t : *triangles) {
        polygons += "3";
        for (int v : t) {
          polygons.push_back(' ');
          append_int(part.first_point + v, &polygons);
        }
        polygons.push_back('\n');
        ++polygon_count;
      }
    } else {
      for (const Spring& s : part.system->description().springs) {
        lines += "2 ";
        append_int(part.first_point + s.a, &lines);
        lines.push_back(' ');
        append_int(part.first_point + s.b, &lines);
        lines.push_back('\n');
        ++line_count;
      }
    }
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
  for (const Part& part : parts_) {
    for (int n = 0; n < part.system->node_count(); ++n) {
      const int dof = part.system->dof_of_node(n);
      // A pinned node where its motion (if any) puts it at t.
      const Eigen::Vector3d pin =
          dof >= 0 ? Eigen::Vector3d::Zero() : part.system->pinned_position(n, t);
      for (int k = 0; k < 3; ++k) {
        if (k > 0) out.push_back(' ');
        append_number(dof >= 0 ? x[part.q_offset + dof + k] : pin[k], &out);
      }
      out.push_back('\n');
    }
  }
  out += topology_;
  out += "POINT_DATA " + std::to_string(point_count_) + "\nVECTORS velocity double\n";
  for (const Part& part : parts_) {
    for (int n = 0; n < part.system->node_count(); ++n) {
      const int dof = part.system->dof_of_node(n);
      for (int k = 0; k < 3; ++k) {
        if (k > 0) out.push_back(' ');
        append_number(dof >= 0 ? x[part.v_offset + dof + k] : part.system->pinned_velocity(n, t)[k],
                      &out);
      }
      out.push_back('\n');
    }
  }
  out += "SCALARS component int 1\nLOOKUP_TABLE default\n";
  for (size_t p = 0; p < parts_.size(); ++p) {
    for (int n = 0; n < parts_[p].system->node_count(); ++n) {
      append_int(static_cast<long>(p), &out);
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
