#include "scenarios/python/overrides.h"

#include <pybind11/numpy.h>

#include <cmath>
#include <cstdio>
#include <utility>

#include "sim/config.h"

namespace py = pybind11;

namespace flexbench::python {
namespace {

std::string NumberText(double v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

std::string TypeName(const py::handle& v) {
  return py::str(py::type::handle_of(v).attr("__name__")).cast<std::string>();
}

// `text` as a YAML double-quoted scalar: always a string, never syntax.
std::string QuotedYaml(const std::string& text) {
  std::string s = "\"";
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') {
      s += '\\';
      s += ch;
    } else if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", c);
      s += buf;
    } else {
      s += ch;  // UTF-8 from Python passes through
    }
  }
  return s + "\"";
}

// Converts Python values to YAML text. `what` names the override or parameter in every error;
// containers on the path being converted are remembered, so a list or dict that contains itself
// is an error rather than an endless recursion.
class YamlWriter {
 public:
  explicit YamlWriter(std::string what) : what_(std::move(what)) {}

  // A top-level str is YAML text, as a --set value is; a str inside a list or dict is a string.
  std::string Top(const py::handle& v) {
    if (py::isinstance<py::str>(v)) return Utf8(v, what_);
    return Value(v, 0);
  }

 private:
  // A list or dict may hold the same object many times over without containing itself
  // ([v, v] of [v, v] ...): 40 levels are 2**40 values. The scenario parser refuses more than
  // kMaxYamlNodes values or kMaxConfigFileBytes of text anyway, so the conversion stops there.
  std::string Leaf(std::string text) {
    bytes_ += text.size();
    if (bytes_ > kMaxConfigFileBytes) {
      throw ValueErrorMessage(what_ + ": more than " + std::to_string(kMaxConfigFileBytes >> 20) +
                              " MiB as YAML text");
    }
    return text;
  }

  // Python refuses to write an int of more than sys.get_int_max_str_digits() digits as text.
  std::string IntText(const py::handle& v) {
    try {
      return py::str(v).cast<std::string>();
    } catch (py::error_already_set& e) {
      if (!e.matches(PyExc_ValueError)) throw;
      throw ValueErrorMessage(what_ + ": an int with more digits than Python writes as text");
    }
  }

  std::string Value(const py::handle& v, int depth) {
    if (++values_ > kMaxYamlNodes) {
      throw ValueErrorMessage(what_ + ": more than " + std::to_string(kMaxYamlNodes) +
                              " values (a list or dict that holds the same object many times?)");
    }
    if (v.is_none()) return Leaf("null");
    if (py::isinstance<py::bool_>(v)) return Leaf(v.cast<bool>() ? "true" : "false");
    if (py::isinstance<py::int_>(v)) return Leaf(IntText(v));
    if (py::isinstance<py::float_>(v)) return Leaf(NumberText(v.cast<double>()));
    if (py::isinstance<py::str>(v)) return Leaf(QuotedYaml(Utf8(v, what_)));
    const bool is_dict = py::isinstance<py::dict>(v);
    const bool is_list = py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v);
    const bool is_array =
        !is_dict && !is_list && (py::isinstance<py::array>(v) || py::hasattr(v, "tolist"));
    if (!is_dict && !is_list && !is_array) {
      throw ValueErrorMessage(what_ + ": cannot express a value of type " + TypeName(v) +
                              " in a scenario file");
    }
    if (depth >= kMaxValueDepth) {
      throw ValueErrorMessage(what_ + ": nested deeper than " + std::to_string(kMaxValueDepth) +
                              " levels");
    }
    for (const PyObject* open : path_) {
      if (open == v.ptr()) {
        throw ValueErrorMessage(what_ + ": a " + TypeName(v) +
                                " that contains itself cannot be written as YAML");
      }
    }
    path_.push_back(v.ptr());
    std::string s;
    if (is_array) {
      s = Value(v.attr("tolist")(), depth + 1);  // numpy arrays and scalars
    } else if (is_dict) {
      s = "{";
      bool first = true;
      for (const auto& [key, value] : py::reinterpret_borrow<py::dict>(v)) {
        if (!py::isinstance<py::str>(key) &&
            !(py::isinstance<py::int_>(key) && !py::isinstance<py::bool_>(key))) {
          throw ValueErrorMessage(what_ + ": a dict key must be a str, got " + TypeName(key));
        }
        s += (first ? "" : ", ") + Leaf(QuotedYaml(Utf8(py::str(key), what_ + " (a key)"))) + ": " +
             Value(value, depth + 1);
        first = false;
      }
      s += "}";
    } else {
      s = "[";
      bool first = true;
      for (const auto& item : v) {
        s += (first ? "" : ", ") + Value(item, depth + 1);
        first = false;
      }
      s += "]";
    }
    path_.pop_back();
    return s;
  }

  std::string what_;
  std::vector<const PyObject*> path_;
  size_t values_ = 0;  // converted so far, containers included
  size_t bytes_ = 0;   // of the scalars' text so far
};

}  // namespace

std::string Utf8(const py::handle& s, const std::string& what) {
  Py_ssize_t size = 0;
  const char* data = PyUnicode_AsUTF8AndSize(s.ptr(), &size);
  if (!data) {
    PyErr_Clear();
    throw ValueErrorMessage(what +
                            ": a str that is not valid Unicode (a lone surrogate such as "
                            "'\\udcff')");
  }
  return std::string(data, static_cast<size_t>(size));
}

bool IsPlainDottedKey(const std::string& key, bool allow_dots) {
  bool part_empty = true;
  for (const char c : key) {
    if (c == '.' && allow_dots) {
      if (part_empty) return false;
      part_empty = true;
    } else if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
               c == '_') {
      part_empty = false;
    } else {
      return false;
    }
  }
  return !part_empty;
}

std::string YamlText(const py::handle& v, const std::string& what) {
  return YamlWriter(what).Top(v);
}

std::vector<std::string> OverrideArgs(const py::object& overrides) {
  std::vector<std::string> set;
  if (overrides.is_none()) return set;
  const auto check_key = [](const std::string& key) {
    if (!IsPlainDottedKey(key)) {
      throw ValueErrorMessage("overrides: key '" + CapForMessage(key) +
                              "' is not a dotted name (letters, digits and '_' separated by "
                              "'.', such as 'detector.threads')");
    }
  };
  if (py::isinstance<py::dict>(overrides)) {
    for (const auto& [key, value] : py::reinterpret_borrow<py::dict>(overrides)) {
      if (!py::isinstance<py::str>(key)) {
        throw ValueErrorMessage("overrides: a key must be a str, got " + TypeName(key));
      }
      const std::string k = Utf8(key, "overrides: a key");
      check_key(k);
      set.push_back(k + "=" + YamlText(value, "overrides['" + k + "']"));
    }
    return set;
  }
  // Neither a str nor what cannot be iterated (an int, a float) is a list of overrides.
  if (py::isinstance<py::str>(overrides) || !py::isinstance<py::iterable>(overrides)) {
    throw ValueErrorMessage("overrides: expected a dict or a list of 'KEY=VALUE' strings, got " +
                            TypeName(overrides));
  }
  for (const auto& item : overrides) {
    if (!py::isinstance<py::str>(item)) {
      throw ValueErrorMessage("overrides: expected a dict or a list of 'KEY=VALUE' strings");
    }
    std::string arg = Utf8(item, "overrides: an item");
    // Without '=' the runner's own message says what is missing.
    const size_t eq = arg.find('=');
    if (eq != std::string::npos) check_key(arg.substr(0, eq));
    set.push_back(std::move(arg));
  }
  return set;
}

}  // namespace flexbench::python
