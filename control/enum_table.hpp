#pragma once
/// @file
/// One checked name table per enum, as libgpiod's C++ bindings map every C
/// enum: the names in enumerator order, a size check at compile time, and
/// bounded conversions both ways. Bytes from the wire (DDS messages, commands)
/// go through `from_wire`, which refuses values the enum does not have, so no
/// received byte ever becomes an enumerator the code does not know or an array
/// index past a table. Pure constexpr: no allocation, no exceptions, usable on
/// the real-time path.
///
/// Use, next to the enum:
/// ```
/// enum class Colour : std::uint8_t { red, green };
/// inline constexpr auto kColourNames = enum_table<Colour::red, Colour::green>({"red", "green"});
/// constexpr const auto& names_of(Colour) noexcept { return kColourNames; }  // found by from_wire/parse_enum
/// constexpr std::string_view to_string(Colour c) noexcept { return kColourNames.to_string(c); }
/// ```

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>
#include <type_traits>

namespace pvcgel {

/// Names of the contiguous enumerators `first() .. first() + N - 1`, in order.
template <typename E, std::size_t N>
class EnumTable {
  static_assert(std::is_enum_v<E>);

 public:
  using Underlying = std::underlying_type_t<E>;

  constexpr EnumTable(E first, const std::array<std::string_view, N>& names) noexcept : first_(first), names_(names) {}

  /// The enumerator's name; "?" for a value outside the table (only a cast can make one).
  [[nodiscard]] constexpr std::string_view to_string(E e) const noexcept {
    const auto i = index(static_cast<long long>(static_cast<Underlying>(e)));
    return i ? names_[*i] : std::string_view("?");
  }
  /// The enumerator named `name`; empty when no enumerator has that name.
  [[nodiscard]] constexpr std::optional<E> parse(std::string_view name) const noexcept {
    for (std::size_t i = 0; i < N; ++i)
      if (names_[i] == name) return at(i);
    return std::nullopt;
  }
  /// The enumerator whose value is `value` (an octet received from outside); empty when there is none.
  [[nodiscard]] constexpr std::optional<E> from_wire(std::uint8_t value) const noexcept {
    const auto i = index(static_cast<long long>(value));
    if (!i) return std::nullopt;
    return at(*i);
  }
  /// All names, in enumerator order (for messages listing the choices).
  [[nodiscard]] constexpr const std::array<std::string_view, N>& names() const noexcept { return names_; }
  /// All enumerators, in order (to visit each without casting an integer to the enum).
  [[nodiscard]] constexpr std::array<E, N> enumerators() const noexcept {
    std::array<E, N> all{};
    for (std::size_t i = 0; i < N; ++i) all[i] = at(i);
    return all;
  }
  /// The smallest enumerator and the number of enumerators.
  [[nodiscard]] constexpr E first() const noexcept { return first_; }
  [[nodiscard]] static constexpr std::size_t size() noexcept { return N; }

 private:
  [[nodiscard]] constexpr std::optional<std::size_t> index(long long value) const noexcept {
    const long long i = value - static_cast<long long>(static_cast<Underlying>(first_));
    if (i < 0 || i >= static_cast<long long>(N)) return std::nullopt;
    return static_cast<std::size_t>(i);
  }
  [[nodiscard]] constexpr E at(std::size_t i) const noexcept {
    return static_cast<E>(static_cast<Underlying>(static_cast<long long>(static_cast<Underlying>(first_)) +
                                                   static_cast<long long>(i)));
  }

  E first_;
  std::array<std::string_view, N> names_;
};

/// The table of the enumerators `First .. Last` (contiguous, in declaration
/// order). Naming the last enumerator and listing the names side by side makes
/// a mismatch a compile error: a table that misses an enumerator, or names one
/// too many, does not build.
template <auto First, auto Last, std::size_t N>
consteval auto enum_table(const std::string_view (&names)[N]) {
  using E = decltype(First);
  static_assert(std::is_enum_v<E> && std::is_same_v<E, decltype(Last)>, "First and Last are enumerators of one enum");
  using U = std::underlying_type_t<E>;
  static_assert(static_cast<long long>(static_cast<U>(Last)) - static_cast<long long>(static_cast<U>(First)) + 1 ==
                    static_cast<long long>(N),
                "the name table must name every enumerator from First to Last, once each");
  std::array<std::string_view, N> a{};
  for (std::size_t i = 0; i < N; ++i) a[i] = names[i];
  return EnumTable<E, N>(First, a);
}

/// `E`'s enumerator for an octet received from outside; empty for an unknown value.
/// Finds the table through `names_of(E)` declared beside the enum.
template <typename E>
constexpr std::optional<E> from_wire(std::uint8_t value) noexcept {
  return names_of(E{}).from_wire(value);
}

/// `E`'s enumerator named `name`; empty for an unknown name.
template <typename E>
constexpr std::optional<E> parse_enum(std::string_view name) noexcept {
  return names_of(E{}).parse(name);
}

/// The octet an enumerator travels as.
template <typename E>
constexpr std::uint8_t to_wire(E e) noexcept {
  static_assert(sizeof(E) == 1, "only one-octet enums travel on the wire");
  return static_cast<std::uint8_t>(e);
}

}  // namespace pvcgel
