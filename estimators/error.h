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

// A caller's bug (a broken precondition of the code, never the user's input: an enum out of
// range, buffers of the wrong size, data of another model) throws std::invalid_argument: the
// runner reports it as an internal error (exit 1), not as bad input.

// A simulation that diverged or did not converge; names the model and the step.
class SimulationError : public std::runtime_error {
 public:
  explicit SimulationError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace flexbench
