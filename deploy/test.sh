#!/usr/bin/env bash
# Installs what is missing, builds and runs the whole test suite with ctest:
# first a check that every C++ file matches .clang-format, then a Release
# build with warnings as errors (binaries in build/bin), then
# the same tests under AddressSanitizer + UndefinedBehaviorSanitizer (clang),
# which also builds the fuzzers and runs each on its seed corpus, and last the
# streaming server's tests under ThreadSanitizer.
#
#   deploy/test.sh               everything (what CI runs)
#   deploy/test.sh --no-sanitize only the Release build and its tests
#   deploy/test.sh --sanitize    only the sanitizer build and its tests
set -euo pipefail
cd "$(dirname "$0")/.."

release=1
sanitize=1
case "${1:-}" in
  --no-sanitize) sanitize=0 ;;
  --sanitize) release=0 ;;
  "") ;;
  -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
  *) echo "test.sh: unknown option '$1' (try --help)" >&2; exit 2 ;;
esac

deploy/install-deps.sh

start=$(date +%s)
echo "== Formatting (.clang-format) =="
mapfile -t sources < <(git ls-files '*.cpp' '*.h' 2>/dev/null || find common protocol server client tests -name '*.cpp' -o -name '*.h')
unformatted=()
for f in "${sources[@]}"; do
  clang-format --dry-run -Werror "$f" >/dev/null 2>&1 || unformatted+=("$f")
done
if [ ${#unformatted[@]} -gt 0 ]; then
  echo "test.sh: ${#unformatted[@]} files do not match .clang-format (run clang-format -i on them):" >&2
  printf '  %s\n' "${unformatted[@]}" >&2
  exit 1
fi
echo "${#sources[@]} files formatted"
if [ "$release" = 1 ]; then
  echo "== Release build (warnings are errors) =="
  cmake --preset ci >/dev/null
  cmake --build --preset ci
  echo "== Release tests =="
  ctest --preset ci
fi
if [ "$sanitize" = 1 ]; then
  echo "== AddressSanitizer + UndefinedBehaviorSanitizer build (clang) =="
  cmake --preset asan >/dev/null
  cmake --build --preset asan
  echo "== Sanitizer tests =="
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 ctest --preset asan
  echo "== ThreadSanitizer build of the streaming server's tests (clang) =="
  cmake --preset tsan >/dev/null
  cmake --build --preset tsan --target test_stream
  echo "== ThreadSanitizer tests =="
  TSAN_OPTIONS="halt_on_error=1 suppressions=$PWD/tests/tsan.supp" ctest --preset tsan -L '^test_stream$'
fi
echo "== all tests passed in $(( $(date +%s) - start )) s =="
