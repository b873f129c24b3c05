// libFuzzer target for the URDF loader. parse_urdf documents InputError as
// its only failure for bad input: that is caught here. Any other exception
// escapes (std::terminate, a crash to libFuzzer), as do sanitizer reports,
// urdfdom's and tinyxml's included. The text is parsed in memory: the loader
// opens no other file (meshes are never read), so no temporary file is needed.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/model/urdf.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string xml(reinterpret_cast<const char*>(data), size);
  // Both roots: a floating base adds a body and changes which subtrees move.
  for (bool floating_base : {false, true}) {
    stiffsim::UrdfOptions options;
    options.floating_base = floating_base;
    std::vector<std::string> notes;
    try {
      stiffsim::RigidTree tree = stiffsim::parse_urdf(xml, "fuzz.urdf", options, &notes);
    } catch (const stiffsim::InputError&) {
      // Rejected with a message: the documented behaviour.
    }
  }
  return 0;
}
