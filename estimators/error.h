// Error types shared by every layer. estimators/ is the bottom of the dependency graph, so the
// shared error type lives here (pure C++).
#pragma once

#include <stdexcept>
#include <string>

namespace flexbench {

// Bad input from a user: a file, key, line or value that is wrong. The runner prints the
// message as one line and exits with code 2. Messages name the file, key or line.
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

// A simulation that diverged or did not converge; names the model and the step.
class SimulationError : public std::runtime_error {
 public:
  explicit SimulationError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace flexbench
