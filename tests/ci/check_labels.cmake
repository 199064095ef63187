# Checks that the ctest labels given to vistream_add_test reach every test
# (CMake 3.25's gtest_discover_tests kept only the first label, so the
# sanitizer passes, which exclude `slow`, ran the slow tests). Run by ctest:
#   cmake -DCTEST=<ctest> -DBUILD_DIR=<build dir> -P check_labels.cmake
# Known answer: both slow executables' suites carry the label `slow`, and no
# test of the fast `test_stream` executable does.
foreach(var CTEST BUILD_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_labels: -D${var}=... is required")
  endif()
endforeach()

function(tests_with_label label out)
  execute_process(COMMAND ${CTEST} --test-dir ${BUILD_DIR} -N -L ${label}
    OUTPUT_VARIABLE text RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "check_labels: ctest -N -L ${label} failed (${status})")
  endif()
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

tests_with_label("^slow$" slow)
foreach(suite WorkBound. NetworkFuzz. PvsGroundTruth.)
  if(NOT slow MATCHES "Test +#[0-9]+: [^\n]*${suite}")
    message(FATAL_ERROR "check_labels: no ${suite}* test carries the label 'slow':\n${slow}")
  endif()
endforeach()

tests_with_label("^test_stream$" stream)
if(NOT stream MATCHES "StreamServer\\.")
  message(FATAL_ERROR "check_labels: the label 'test_stream' reaches no StreamServer test:\n${stream}")
endif()
if(stream MATCHES "WorkBound\\.|NetworkFuzz\\.")
  message(FATAL_ERROR "check_labels: slow tests carry the label 'test_stream':\n${stream}")
endif()
message(STATUS "check_labels: slow and executable labels reach their tests")
