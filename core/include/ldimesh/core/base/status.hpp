// The error model (after Draco's and Abseil's Status): every fallible operation on data, files,
// messages and the network returns a Status — a code saying what kind of thing went wrong and a
// message saying which. Exceptions are for programming errors and for core's argument checks;
// one guard at each API boundary (the C API, the adaptor's create, worker and caster threads)
// turns them into a Status, so nothing escapes to the solver.
//
// Threads: a Status is a value; nothing here is shared.
#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace ldimesh {

// What went wrong, by cause. The C API's codes follow from these (ldimesh.h).
enum class StatusCode {
  ok = 0,
  invalid_argument,  // the caller passed something malformed (NULL, wrong sizes, bad values)
  invalid_options,   // the adaptor's options document (the message names the key)
  corrupt_input,     // data that fails validation: a file, a message, an encoded buffer
  io,                // a file, socket or MPI call failed
  out_of_memory,     // an allocation failed
  other_rank,        // a collective step failed on another rank (its message is there)
  internal,          // a bug: an unexpected exception or state
};

// "invalid argument", "corrupt input", …
const char* to_string(StatusCode code);

class Status {
 public:
  static Status ok() { return Status(); }
  static Status error(StatusCode code, std::string message) {
    assert(code != StatusCode::ok);
    return Status(code, std::move(message));
  }
  static Status invalid_argument(std::string m) {
    return error(StatusCode::invalid_argument, std::move(m));
  }
  static Status invalid_options(std::string m) {
    return error(StatusCode::invalid_options, std::move(m));
  }
  static Status corrupt_input(std::string m) {
    return error(StatusCode::corrupt_input, std::move(m));
  }
  static Status io(std::string m) { return error(StatusCode::io, std::move(m)); }
  static Status out_of_memory(std::string m) {
    return error(StatusCode::out_of_memory, std::move(m));
  }
  static Status other_rank(std::string m) { return error(StatusCode::other_rank, std::move(m)); }
  static Status internal(std::string m) { return error(StatusCode::internal, std::move(m)); }

  bool is_ok() const { return code_ == StatusCode::ok; }
  explicit operator bool() const { return is_ok(); }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }

  // The same code with `prefix` before the message ("reading 'a.glb': " + message).
  Status prefixed(std::string_view prefix) const {
    return is_ok() ? *this : Status(code_, std::string(prefix) + message_);
  }

 private:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}
  StatusCode code_ = StatusCode::ok;
  std::string message_;
};

// A value, or the Status of why there is none (after Abseil's and Draco's StatusOr): what code
// that returns a value returns, instead of an out-parameter beside a Status. An ok Status without
// a value is a bug, kept as an internal error.
template <class T>
class StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}         // NOLINT(google-explicit-constructor)
  StatusOr(Status status) : status_(std::move(status)) {  // NOLINT(google-explicit-constructor)
    assert(!status_.is_ok());
    if (status_.is_ok()) status_ = Status::internal("StatusOr: an ok Status without a value");
  }

  bool ok() const { return status_.is_ok(); }
  explicit operator bool() const { return ok(); }
  const Status& status() const& { return status_; }
  Status status() && { return std::move(status_); }
  // The value; only where ok().
  T& value() & {
    assert(ok());
    return *value_;
  }
  const T& value() const& {
    assert(ok());
    return *value_;
  }
  T&& value() && {
    assert(ok());
    return std::move(*value_);
  }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

 private:
  Status status_ = Status::ok();
  std::optional<T> value_;
};

// The Status of the exception being handled (call inside a catch block): std::bad_alloc → out
// of memory, std::invalid_argument → invalid argument, anything else → internal. `where` leads
// the message ("ldimesh_execute: ").
Status status_from_current_exception(std::string_view where);

// The guard at an API boundary: runs body() (which returns a Status) and turns any exception
// into a Status. Nothing escapes.
template <class Body>
Status guard(std::string_view where, Body&& body) noexcept {
  try {
    return body();
  } catch (...) {
    return status_from_current_exception(where);
  }
}

}  // namespace ldimesh

// Return the Status of `expr` from the enclosing function where it is not ok.
#define LDIMESH_RETURN_IF_ERROR(expr)                                         \
  do {                                                                        \
    if (::ldimesh::Status ldimesh_status_ = (expr); !ldimesh_status_.is_ok()) \
      return ldimesh_status_;                                                 \
  } while (0)

// `lhs` = the value of the StatusOr `expr`, or return its Status from the enclosing function:
//   LDIMESH_ASSIGN_OR_RETURN(const Plan plan, make_plan(...));
// It expands to statements (not the body of an if without braces), one use per line, and `lhs`
// holds no comma (a type with one: an alias first).
#define LDIMESH_ASSIGN_OR_RETURN(lhs, expr) \
  LDIMESH_ASSIGN_OR_RETURN_IMPL(LDIMESH_STATUS_CONCAT(ldimesh_or_, __LINE__), lhs, expr)
#define LDIMESH_ASSIGN_OR_RETURN_IMPL(or_value, lhs, expr) \
  auto or_value = (expr);                                  \
  if (!or_value.ok()) return std::move(or_value).status(); \
  lhs = std::move(or_value).value()
#define LDIMESH_STATUS_CONCAT(a, b) LDIMESH_STATUS_CONCAT_IMPL(a, b)
#define LDIMESH_STATUS_CONCAT_IMPL(a, b) a##b
