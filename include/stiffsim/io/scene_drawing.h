#pragma once
// What a picture of a scene needs at one instant: per drawable component,
// its drawing (drawing.h), made by the component itself (System::draw:
// ParticleSystem and ArticulatedSystem say what they draw) with the points
// the scene's attachments hold on it and its surface triangles. The Python
// module hands it to scripts/render, which only plots. Components with no
// geometry (pure ODE systems) are left out.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "stiffsim/drawing.h"
#include "stiffsim/scene.h"

namespace stiffsim {

// The drawing of `scene` at time t and state x = [q; v; z]. `surfaces`, if
// given, holds per component its triangles in the component's node
// numbering (SceneConfig::surfaces); triangles out of a component's range
// are ignored in favour of its springs, as the VTK writer does. Throws
// InputError if x does not have the scene's size. Non-finite state values
// (the last row of a failed run) are drawn as they are.
std::vector<ComponentDrawing> draw_scene(
    const Scene& scene, const std::vector<std::vector<std::array<int, 3>>>& surfaces, double t,
    const Eigen::VectorXd& x);

}  // namespace stiffsim
