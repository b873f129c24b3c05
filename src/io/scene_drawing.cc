#include "stiffsim/io/scene_drawing.h"

#include <utility>

#include "stiffsim/error.h"

namespace stiffsim {

std::vector<ComponentDrawing> draw_scene(
    const Scene& scene, const std::vector<std::vector<std::array<int, 3>>>& surfaces, double t,
    const Eigen::VectorXd& x) {
  const Dimensions dims = scene.dimensions();
  if (x.size() != dims.nx()) {
    throw InputError("drawing scene '" + scene.name() + "': state of size " +
                     std::to_string(x.size()) + ", expected " + std::to_string(dims.nx()));
  }
  std::vector<ComponentDrawing> out;
  for (int i = 0; i < scene.component_count(); ++i) {
    const System& component = scene.component(i);
    const int q_offset = scene.offsets(i).nq;
    const int v_offset = dims.nq + scene.offsets(i).nv;
    DrawingRequest request;
    if (i < static_cast<int>(surfaces.size())) request.triangles = &surfaces[i];
    for (const Attachment& at : scene.attachments()) {
      for (const AttachmentPoint* p : {&at.a, &at.b}) {
        if (p->component == i) request.hooks.push_back(*p);
      }
    }
    const Dimensions d = component.dimensions();
    ComponentDrawing drawing;
    if (component.draw(t, x.segment(q_offset, d.nq), x.segment(v_offset, d.nv), request,
                       &drawing)) {
      drawing.component = i;
      out.push_back(std::move(drawing));
    }
  }
  return out;
}

}  // namespace stiffsim
