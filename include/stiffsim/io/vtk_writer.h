#pragma once
// Mesh frames for ParaView: one legacy VTK PolyData file (ASCII)
// DIR/<scene>_<NNNNN>.vtk per sample with every particle node (pinned ones at
// their fixed positions) as POINTS, surfaces as POLYGONS (cloth grids, OBJ
// meshes) or springs as LINES (ropes), and the node velocities and component
// index as point data. DIR/<scene>.vtk.series lists the frames with their
// times; ParaView (5.5 and later) opens it as one time-dependent dataset.
//
// Why not a .pvd: ParaView's PVD reader (vtkXMLCollectionReader) only
// instantiates XML readers (.vtp, .vtu, ...), so a .pvd that points at legacy
// .vtk files does not open.
//
// Every file is written under a temporary name and renamed when complete;
// the series file is written only by finish() or finish_incomplete().

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "stiffsim/integrators/sample_sink.h"
#include "stiffsim/scene.h"

namespace stiffsim {

class ParticleSystem;

class VtkWriter : public FileSink {
 public:
  // As a run's sink every sample is a frame; the run's end finishes the file.
  bool on_sample(double t, const Eigen::VectorXd& x) override {
    write_frame(t, x);
    return true;
  }

  // `surfaces`, if given, holds per component of `scene` its triangles in the
  // component's node numbering (SceneConfig::surfaces); components without
  // triangles are drawn as their springs. Creates `directory` if needed.
  // Throws InputError if the directory cannot be created or the scene has no
  // particle component to draw.
  VtkWriter(std::string directory, const Scene& scene,
            const std::vector<std::vector<std::array<int, 3>>>& surfaces = {});

  // One frame of the state x = [q; v; z] at time t.
  void write_frame(double t, const Eigen::VectorXd& x);
  // Writes the series file listing the frames so far.
  void finish() override;
  // As finish(), and the series file records why the run stopped.
  void finish_incomplete(const std::string& reason) override;

  long frames() const { return static_cast<long>(times_.size()); }
  // Path of the series file finish() writes.
  std::string series_path() const;
  // Path of frame `index`.
  std::string frame_path(long index) const;

 private:
  struct Part {
    const ParticleSystem* system;
    int q_offset;  // of the component's slice in the scene's q
    int v_offset;  // in the scene's x (nq + the component's v offset)
    int first_point;
  };
  void write_series(const std::string& reason);

  std::string directory_;
  std::string scene_name_;
  std::vector<Part> parts_;
  int point_count_ = 0;
  long state_size_ = 0;
  std::string topology_;  // POLYGONS / LINES and the constant point data, same in every frame
  std::vector<double> times_;
  std::string buffer_;
};

}  // namespace stiffsim
