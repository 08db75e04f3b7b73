// libFuzzer target of the Python module's override conversion (scenarios/python/overrides.h):
// the bytes are a small stack program that builds a Python object (scalars, strings that may
// hold lone surrogates, lists, tuples, dicts with keys of any type, numpy arrays, containers
// that contain themselves or each other), which is then passed as run_scenario's `overrides`.
// The strings it returns go through ParseOverride and are applied to a fixed valid scenario
// with ConfigNode::LoadString, as the runner applies --set arguments, and the result is read as
// the scenario's kind reads it.
//
// Run as: build-fuzz/bin/fuzz_python_overrides <new corpus dir> tests/fuzz/corpus/python_overrides
// -rss_limit_mb=2048 -timeout=10 (a value of 1,000,000 nodes, the parser's cap, takes 1-3 s
// under ASan on busy cores: -timeout=1 reports those as timeouts).
//
// Allowed outcomes: success, or what reaches Python as ValueError (ValueErrorMessage, an
// InputError from the scenario parser, a Python ValueError or one of its subclasses). Anything
// else escapes to libFuzzer as a crash.
//
// Program: one opcode byte (taken modulo the number of opcodes) and its operand bytes, until the
// bytes end; a missing operand byte reads as 0. The stack holds at most kMaxStack objects and a
// container takes at most kMaxItems of them. The object converted is the top of the stack.
#include <pybind11/embed.h>
#include <pybind11/numpy.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "estimators/error.h"
#include "scenarios/python/overrides.h"
#include "sim/config.h"

namespace py = pybind11;
using namespace pybind11::literals;

namespace {

constexpr size_t kMaxStack = 64;
constexpr size_t kMaxItems = 16;

// A scenario the runner accepts (scenarios/smoke.yaml without its comments).
constexpr const char* kScenario = R"(scenario: smoke
description: one rendered frame through every layer
kind: smoke
seed: 1
model: ../models/planar3.xml
camera: overview
configuration:
  joint1: 0.35
  joint2: -0.6
  joint3: 0.5
render:
  mode: quality
detector:
  family: tag36h11
  decimate: 1.0
  sigma: 0.0
  threads: 1
gates:
  - {name: tag_detected, metric: detections, op: ">=", threshold: 1}
  - {name: corner_accuracy, metric: corner_rmse_px, op: "<", threshold: 1.0}
)";

// Strings worth combining: the scenario's keys, dotted paths, YAML syntax, '=' and text that
// is a number or a null in YAML.
const char* const kTokens[] = {
    "seed",
    "configuration",
    "configuration.joint1",
    "detector.threads",
    "render.mode",
    "gates",
    "model",
    "kind",
    "estimators.ppoe_ekf.iterations",
    "a.b",
    ".",
    "=",
    "a=",
    ":",
    ",",
    "{",
    "}",
    "[",
    "]",
    "#",
    "\n",
    "- ",
    "&a",
    "*a",
    "!!str",
    "null",
    "~",
    "1e300",
    ".nan",
    "?",
    "\"",
    "'",
    "\\",
    "",
    "a",
    "0",
    "seed=1",
    "key: value",
    "\xe2\x82\xac",
    "\t",
    "|",
};

class Program {
 public:
  Program(const std::uint8_t* data, size_t size) : data_(data), size_(size) {}

  // The object the program builds (None for an empty program).
  py::object Run() {
    while (pos_ < size_) Step();
    return stack_.empty() ? py::none() : stack_.back();
  }

 private:
  std::uint8_t Byte() { return pos_ < size_ ? data_[pos_++] : 0; }

  std::string Bytes(size_t n) {
    n = std::min(n, size_ - pos_);
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }

  template <class T>
  T Scalar() {
    T v{};
    const std::string b = Bytes(sizeof(T));
    std::memcpy(&v, b.data(), b.size());
    return v;
  }

  void Push(py::object o) {
    if (stack_.size() >= kMaxStack) stack_.erase(stack_.begin());
    stack_.push_back(std::move(o));
  }

  // The top `k` objects (oldest first), removed from the stack.
  std::vector<py::object> Take(size_t k) {
    k = std::min({k, kMaxItems, stack_.size()});
    std::vector<py::object> items(stack_.end() - static_cast<std::ptrdiff_t>(k), stack_.end());
    stack_.resize(stack_.size() - k);
    return items;
  }

  // An object on the stack chosen by the next byte (nullptr when the stack is empty).
  py::object* Pick() {
    if (stack_.empty()) return nullptr;
    return &stack_[stack_.size() - 1 - Byte() % stack_.size()];
  }

  void Step() {
    switch (Byte() % 16) {
      case 0:
        Push(py::none());
        break;
      case 1:
        Push(py::bool_(Byte() & 1));
        break;
      case 2:
        Push(py::int_(static_cast<long long>(Scalar<std::int64_t>())));
        break;
      case 3: {  // an int beyond 64 bits, up to 10**5999 (past Python's 4300-digit str limit)
        const unsigned e = Scalar<std::uint16_t>() % 6000;
        PyObject* p = PyNumber_Power(py::int_(10).ptr(), py::int_(e).ptr(), Py_None);
        if (!p) throw py::error_already_set();
        Push(py::reinterpret_steal<py::object>(p) - py::int_(Byte()));
        break;
      }
      case 4:
        Push(py::float_(Scalar<double>()));
        break;
      case 5: {  // arbitrary bytes as str: invalid UTF-8 becomes lone surrogates
        const std::string b = Bytes(Byte() % 64);
        PyObject* s =
            PyUnicode_DecodeUTF8(b.data(), static_cast<Py_ssize_t>(b.size()), "surrogateescape");
        if (!s) throw py::error_already_set();
        Push(py::reinterpret_steal<py::str>(s));
        break;
      }
      case 6:
        Push(py::str(kTokens[Byte() % (sizeof(kTokens) / sizeof(kTokens[0]))]));
        break;
      case 7: {
        py::list l;
        for (py::object& o : Take(Byte())) l.append(o);
        Push(l);
        break;
      }
      case 8: {
        const std::vector<py::object> items = Take(Byte());
        py::tuple t(items.size());
        for (size_t i = 0; i < items.size(); ++i) t[i] = items[i];
        Push(t);
        break;
      }
      case 9: {  // a dict of the top 2k objects as key, value pairs; unhashable keys skipped
        const std::vector<py::object> items = Take(2 * size_t{Byte()});
        py::dict d;
        for (size_t i = 0; i + 1 < items.size(); i += 2) {
          if (PyDict_SetItem(d.ptr(), items[i].ptr(), items[i + 1].ptr()) != 0) PyErr_Clear();
        }
        Push(d);
        break;
      }
      case 10: {  // a reference into a list or dict already on the stack: shared parts, cycles
        py::object* container = Pick();
        py::object* item = Pick();
        if (!container || !item) break;
        if (py::isinstance<py::list>(*container)) {
          container->cast<py::list>().append(*item);
        } else if (py::isinstance<py::dict>(*container)) {
          py::object key = stack_.size() > 1 ? stack_[stack_.size() - 2] : py::str("k");
          if (PyDict_SetItem(container->ptr(), key.ptr(), item->ptr()) != 0) PyErr_Clear();
        } else {
          break;
        }
        made_cycle_ = true;
        break;
      }
      case 11: {
        py::object* o = Pick();
        if (o) Push(*o);
        break;
      }
      case 12: {  // "KEY=VALUE" from the top two objects' str(), scalars only: str() of a list
                  // sharing its items 2^k times is Python's own gigabyte, not the conversion's
        std::vector<py::object> kv = Take(2);
        if (kv.size() < 2) break;
        const auto scalar = [](const py::object& o) {
          return py::isinstance<py::str>(o) || py::isinstance<py::int_>(o) ||
                 py::isinstance<py::float_>(o) || o.is_none();
        };
        if (!scalar(kv[0]) || !scalar(kv[1])) break;
        Push(py::str(kv[0]) + py::str("=") + py::str(kv[1]));
        break;
      }
      case 13: {  // a type the conversion cannot express
        switch (Byte() % 4) {
          case 0:
            Push(py::bytes(Bytes(Byte() % 8)));
            break;
          case 1:
            Push(py::reinterpret_steal<py::object>(PyComplex_FromDoubles(1.0, 2.0)));
            break;
          case 2:
            Push(py::reinterpret_steal<py::object>(PySet_New(nullptr)));
            break;
          default:
            Push(py::module_::import("builtins").attr("object")());
            break;
        }
        break;
      }
      case 14: {  // numpy: the top object as an array (dtype chosen by numpy, or object)
        // Not after a cycle: numpy's search for the shape of a list that contains itself takes
        // seconds, and that is numpy's, not the conversion's.
        if (stack_.empty() || made_cycle_) break;
        py::object np = py::module_::import("numpy");
        try {
          py::object a = (Byte() & 1) ? np.attr("asarray")(stack_.back())
                                      : np.attr("array")(stack_.back(), "dtype"_a = "object");
          stack_.back() = a;
        } catch (py::error_already_set&) {
          // not every object is an array (ragged lists, ...): the stack stays as it was
        }
        break;
      }
      case 15: {  // a numpy scalar
        py::object np = py::module_::import("numpy");
        Push(np.attr("float32")(Scalar<float>()));
        break;
      }
    }
  }

  const std::uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  std::vector<py::object> stack_;
  bool made_cycle_ = false;
};

// What the smoke kind reads (the keys of kScenario, typed), then the unknown-key check, as a
// run reads the scenario. Reading every node instead would cost seconds and gigabytes on a
// value of 1,000,000 nodes (each consumed path is remembered), which no reader does.
void Read(const flexbench::ConfigNode& root) {
  for (const char* key : {"scenario", "description", "kind", "model", "camera"}) {
    root.GetString(key);
  }
  root.GetInt("seed");
  const flexbench::ConfigNode configuration = root.Child("configuration");
  for (const std::string& joint : configuration.Keys()) configuration.GetDouble(joint);
  root.Child("render").GetString("mode");
  const flexbench::ConfigNode detector = root.Child("detector");
  detector.GetString("family");
  detector.GetDouble("decimate");
  detector.GetDouble("sigma");
  detector.GetInt("threads");
  for (const flexbench::ConfigNode& gate : root.Child("gates").Items()) {
    for (const std::string& key : gate.Keys()) gate.Child(key).AsString();
  }
  root.CheckNoUnknownKeys();
}

void Convert(const py::object& overrides) {
  std::vector<flexbench::ConfigOverride> parsed;
  for (const std::string& arg : flexbench::python::OverrideArgs(overrides)) {
    parsed.push_back(flexbench::ParseOverride(arg));
  }
  Read(flexbench::ConfigNode::LoadString(kScenario, "fuzz.yaml", parsed));
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Python's objects come from its own arenas (pymalloc): PYTHONMALLOC=malloc would let ASan see
  // a use after free of an object, but makes every value converted several times slower.
  // Never finalized: the interpreter lives as long as the process, and everything it holds
  // stays reachable for the leak checker. No signal handlers, so libFuzzer keeps SIGINT.
  static py::scoped_interpreter* interpreter = new py::scoped_interpreter(false);
  (void)interpreter;
  py::module_::import("numpy");
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  {
    Program program(data, size);
    py::object overrides;
    try {
      overrides = program.Run();
    } catch (py::error_already_set&) {
      return 0;  // building failed (str() of a huge int, RecursionError, ...): not the subject
    }
    try {
      Convert(overrides);
    } catch (const flexbench::python::ValueErrorMessage&) {
    } catch (const flexbench::InputError&) {
    } catch (py::error_already_set& e) {
      // Reaches Python as itself (the module's translator restores it): ValueError is fine.
      if (!e.matches(PyExc_ValueError)) throw;
    }
  }
  return 0;
}

// Python never frees everything it allocates (interned strings, types, objects linked through
// tagged GC pointers the leak checker cannot follow): leak reports would be Python's own.
extern "C" const char* __asan_default_options() { return "detect_leaks=0"; }
