// Python values as scenario overrides: what run_scenario's and identify's `overrides` and
// make_estimator's parameters become before the scenario parser reads them (`--set KEY=VALUE`
// with the value as YAML text). Kept apart from the module's bindings so that a fuzzer
// (tests/fuzz/fuzz_python_overrides.cc) links it with only the interpreter and sim/config.cc.
//
// Every refusal is a ValueErrorMessage (the module raises it as ValueError); nothing a caller
// passes, however nested or self-referencing, ends in a crash or an endless recursion.
#pragma once

#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace flexbench::python {

// Python's ValueError, raised from C++ with a message.
struct ValueErrorMessage : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Nesting deeper than this in an override or a parameter is refused: no scenario key is that
// deep, and converting has to stop somewhere on a structure that never ends.
inline constexpr int kMaxValueDepth = 64;

// A key of plain names: [A-Za-z0-9_]+ separated by single dots ("detector.threads"); with
// `allow_dots` false, one name. Anything else could carry YAML syntax (':', ',', '{', a
// newline) into the override.
bool IsPlainDottedKey(const std::string& key, bool allow_dots = true);

// The UTF-8 text of the str `s`. A str with a lone surrogate (what os.fsdecode makes of bytes
// that are not UTF-8) has none: ValueErrorMessage naming `what`, as the runner refuses a --set
// value that is not UTF-8.
std::string Utf8(const pybind11::handle& s, const std::string& what);

// `v` as YAML text: a top-level str as it is (YAML text, as a --set value is); None, bool,
// int, float (.nan, .inf), str inside containers (always quoted), list, tuple, dict (str or
// int keys) and numpy arrays or scalars (through tolist()) converted. `what` names the
// override or parameter in every error. A container that contains itself, nesting deeper
// than kMaxValueDepth and any other type are refused.
std::string YamlText(const pybind11::handle& v, const std::string& what);

// overrides: None, a dict {dotted.key: value} (in order) or a list of "KEY=VALUE" strings, as
// the runner's --set arguments. Keys are plain dotted names; values become YAML text with
// strings inside lists and dicts quoted, so nothing the caller passes is read as YAML syntax
// outside its own value.
std::vector<std::string> OverrideArgs(const pybind11::object& overrides);

}  // namespace flexbench::python
