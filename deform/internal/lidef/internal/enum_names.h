// The names of an enum's values, in enum order, declared once per enum (a specialization of EnumNames next to
// the code that writes them): to_string, the parameter table's choices and the readers' parsing all come from
// that one list, so a value cannot be written under one name and read under another.
#pragma once
#include <iterator>
#include <optional>
#include <string>

#include "lidef/deform_params.h"
#include "lidef/lipschitz_bound.h"

namespace lidef {

template <class E>
struct EnumNames;  // static constexpr const char* names[]: one per value, in enum order

// The name of a value.
template <class E>
const char* enum_name(E e) {
  return EnumNames<E>::names[static_cast<int>(e)];
}

// The value of a name; nothing for a name that is not one.
template <class E>
std::optional<E> enum_from_name(const std::string& name) {
  for (int i = 0; i < static_cast<int>(std::size(EnumNames<E>::names)); ++i)
    if (name == EnumNames<E>::names[i]) return static_cast<E>(i);
  return std::nullopt;
}

// "'a', 'b' or 'c'", for messages.
template <class E>
std::string enum_name_list() {
  std::string s;
  const int n = static_cast<int>(std::size(EnumNames<E>::names));
  for (int i = 0; i < n; ++i)
    s += (i == 0 ? "" : i + 1 == n ? " or " : ", ") + std::string("'") + EnumNames<E>::names[i] + "'";
  return s;
}

// The enums of the parameter table (deform_params.h, lipschitz_bound.h).
template <>
struct EnumNames<LipschitzBound> {
  static constexpr const char* names[] = {"first", "third", "combined", "spectral"};
};
template <>
struct EnumNames<RefinementEval> {
  static constexpr const char* names[] = {"per-face", "per-edge", "batched", "far-field"};
};
template <>
struct EnumNames<HessianPrecision> {
  static constexpr const char* names[] = {"single", "double"};
};
template <>
struct EnumNames<BackendKind> {
  static constexpr const char* names[] = {"cpu", "opencl", "auto"};
};
template <>
struct EnumNames<DomainKind> {
  static constexpr const char* names[] = {"mesh", "voxels"};
};
template <>
struct EnumNames<InjectivityMode> {
  static constexpr const char* names[] = {"local", "global"};
};

}  // namespace lidef
