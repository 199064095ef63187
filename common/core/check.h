// Invariant checks: the first of vistream's two error channels.
//
// VS_CHECK* guard invariants inside the program (a broken one is a bug in
// vistream, never a consequence of bad input). On failure they print the
// expression, the values involved and the source location, then abort.
// Untrusted bytes (files, network frames, arguments) must never reach a
// VS_CHECK: they go through the second channel, vistream::InputError (error.h).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>

namespace vistream::detail {

[[noreturn]] inline void checkFailed(const char* file, int line, const char* expr,
                                     const std::string& values) {
  std::fprintf(stderr, "%s:%d: CHECK failed: %s%s%s\n", file, line, expr,
               values.empty() ? "" : " with ", values.c_str());
  std::fflush(stderr);
  std::abort();
}

template <typename A, typename B>
std::string describePair(const char* na, const A& a, const char* nb, const B& b) {
  std::ostringstream os;
  os << na << " = " << a << ", " << nb << " = " << b;
  return os.str();
}

}  // namespace vistream::detail

#define VS_CHECK(cond)                                                           \
  do {                                                                           \
    if (!(cond)) ::vistream::detail::checkFailed(__FILE__, __LINE__, #cond, ""); \
  } while (0)

#define VS_CHECK_OP_(a, b, op)                                                                 \
  do {                                                                                         \
    const auto& vs_a_ = (a);                                                                   \
    const auto& vs_b_ = (b);                                                                   \
    if (!(vs_a_ op vs_b_))                                                                     \
      ::vistream::detail::checkFailed(__FILE__, __LINE__, #a " " #op " " #b,                   \
                                      ::vistream::detail::describePair(#a, vs_a_, #b, vs_b_)); \
  } while (0)

#define VS_CHECK_EQ(a, b) VS_CHECK_OP_(a, b, ==)
#define VS_CHECK_NE(a, b) VS_CHECK_OP_(a, b, !=)
#define VS_CHECK_LT(a, b) VS_CHECK_OP_(a, b, <)
#define VS_CHECK_LE(a, b) VS_CHECK_OP_(a, b, <=)
#define VS_CHECK_GT(a, b) VS_CHECK_OP_(a, b, >)
#define VS_CHECK_GE(a, b) VS_CHECK_OP_(a, b, >=)

#ifdef NDEBUG
#define VS_DCHECK(cond) \
  do {                  \
  } while (0)
#else
#define VS_DCHECK(cond) VS_CHECK(cond)
#endif
