// libFuzzer target for the YAML scene loader. load_scene documents InputError
// as its only failure for bad input: that is caught here. Any other exception
// escapes (std::terminate, a crash to libFuzzer), as do sanitizer reports.

#include <cstddef>
#include <cstdint>

#include "fuzz_tmpdir.h"
#include "stiffsim/error.h"
#include "stiffsim/io/scene_yaml.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (stiffsim_fuzz::names_special_file(data, size)) return -1;  // not added to the corpus
  if (stiffsim_fuzz::asks_for_a_large_scene(data, size)) return -1;
  const std::string path = stiffsim_fuzz::write_input("scene.yaml", data, size);
  try {
    stiffsim::SceneConfig config = stiffsim::load_scene(path);
  } catch (const stiffsim::InputError&) {
    // Rejected with a message: the documented behaviour.
  }
  return 0;
}
