// libFuzzer driver of one target of fuzz_entry.h, chosen at compile time
// (FLEXBENCH_FUZZ_TARGET, tests/fuzz/CMakeLists.txt): build/bin/fuzz_<target>.
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "tests/fuzz/fuzz_entry.h"

#define FLEXBENCH_STR2(x) #x
#define FLEXBENCH_STR(x) FLEXBENCH_STR2(x)

namespace {
flexbench::fuzz::Entry g_entry = nullptr;
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  flexbench::fuzz::Init();
  for (const flexbench::fuzz::Target& t : flexbench::fuzz::Targets()) {
    if (std::strcmp(t.name, FLEXBENCH_STR(FLEXBENCH_FUZZ_TARGET)) == 0) g_entry = t.entry;
  }
  if (!g_entry) {
    std::fprintf(stderr, "no fuzz target %s\n", FLEXBENCH_STR(FLEXBENCH_FUZZ_TARGET));
    std::abort();
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  g_entry(data, size);  // an InputError is a clean rejection; anything else reaches libFuzzer
  return 0;
}
