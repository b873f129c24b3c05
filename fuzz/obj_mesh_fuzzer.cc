// libFuzzer target for the OBJ loader. load_obj documents InputError as its
// only failure for bad input: that is caught here. Any other exception escapes
// (std::terminate, a crash to libFuzzer), as do sanitizer reports.

#include <cstddef>
#include <cstdint>

#include "fuzz_tmpdir.h"
#include "stiffsim/error.h"
#include "stiffsim/io/obj_mesh.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = stiffsim_fuzz::write_input("mesh.obj", data, size);
  try {
    stiffsim::TriangleMesh mesh = stiffsim::load_obj(path);
  } catch (const stiffsim::InputError&) {
    // Rejected with a message: the documented behaviour.
  }
  return 0;
}
