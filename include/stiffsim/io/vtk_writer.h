#pragma once
// Mesh frames for ParaView: one legacy VTK PolyData file (ASCII)
// DIR/<scene>_<NNNNN>.vtk per sample holding the scene's drawing
// (scene_drawing.h: every particle node, pinned ones where their paths put
// them, and the bodies of URDF trees) as POINTS, surfaces as POLYGONS (cloth
// grids, OBJ meshes) and the other segments as LINES (a rope's stretch
// springs, a tree's links), with the points' velocities and component index
// (in the scene) as point data. DIR/<scene>.vtk.series lists the frames with their
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

class VtkWriter : public FileSink {
 public:
  // As a run's sink every sample is a frame; the run's end finishes the file.
  bool on_sample(double t, const Eigen::VectorXd& x) override {
    write_frame(t, x);
    return true;
  }

  // `surfaces`, if given, holds per component of `scene` its triangles in the
  // component's node numbering (SceneConfig::surfaces); components without
  // triangles are drawn as their segments. Creates `directory` if needed.
  // Throws InputError if the directory cannot be created or the scene has
  // nothing to draw. The scene must outlive the writer.
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
  void write_series(const std::string& reason);

  std::string directory_;
  std::string scene_name_;
  const Scene& scene_;
  std::vector<std::vector<std::array<int, 3>>> surfaces_;
  long point_count_ = 0;
  long state_size_ = 0;
  std::string topology_;  // POLYGONS / LINES and the constant point data, same in every frame
  std::vector<double> times_;
  std::string buffer_;
};

}  // namespace stiffsim
