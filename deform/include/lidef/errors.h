// lidef's exception types. Every failure a user can cause names the file and the element involved.
#pragma once
#include <stdexcept>
#include <string>

namespace lidef {

// Base class of all lidef errors.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Bad user input: a file that cannot be read, a malformed or unusable model, a bad parameter.
// what() = "<file>:<line>: <message>" when a location is known.
class InputError : public Error {
 public:
  InputError(const std::string& file, const std::string& message, long line = 0)
      : Error(format(file, message, line)), file_(file), line_(line), message_(message) {}
  const std::string& file() const { return file_; }
  long line() const { return line_; }
  const std::string& message() const { return message_; }

 private:
  static std::string format(const std::string& file, const std::string& message, long line) {
    std::string s = file;
    if (line > 0) s += ":" + std::to_string(line);
    if (!s.empty()) s += ": ";
    return s + message;
  }
  std::string file_;
  long line_;
  std::string message_;
};

// A numerical routine could not produce a trustworthy result (e.g. an eigen-solver did not converge).
class NumericalError : public Error {
 public:
  using Error::Error;
};

}  // namespace lidef
