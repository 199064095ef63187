// Compiling a hot loop for wider vectors than the baseline x86-64 build has.
//
// VISTREAM_AVX2_CLONES before a function's definition has GCC compile it
// twice, for AVX2 and for the baseline, and pick one when the program loads
// by what the CPU offers (target_clones). Only AVX2 is enabled, not FMA, so
// the compiler cannot fuse a multiply and an add: both clones round every
// operation alike and return the same bits, whichever CPU runs them. Use it
// on loops written to auto-vectorize (no calls, no branches in the body).
// Elsewhere (Clang, other architectures) it is empty and the baseline runs.
#pragma once

#include <cstdlib>  // on glibc, defines __GLIBC__

// target_clones needs the loader's ifunc support: glibc on x86-64 Linux.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && \
    defined(__GLIBC__)
#define VISTREAM_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define VISTREAM_AVX2_CLONES
#endif
