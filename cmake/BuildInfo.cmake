# Build provenance for every report: the git commit is read at build time (not configure time),
# so a report never names a stale commit after an incremental rebuild.
string(TOUPPER "${CMAKE_BUILD_TYPE}" _sphperf_bt)
get_directory_property(_sphperf_opts COMPILE_OPTIONS)
# And the definitions that choose code (SPHPERF_PREFER_AVX2_KERNELS: which kernels Cell+Sorted
# runs), as -D flags.
get_directory_property(_sphperf_defs COMPILE_DEFINITIONS)
list(TRANSFORM _sphperf_defs PREPEND "-D")
string(JOIN " " SPHPERF_BUILD_FLAGS ${CMAKE_CXX_FLAGS} ${CMAKE_CXX_FLAGS_${_sphperf_bt}} ${_sphperf_opts}
       ${_sphperf_defs})
set(SPHPERF_BUILD_INFO_CPP ${CMAKE_BINARY_DIR}/generated/build_info.cpp)

add_custom_target(sphperf_build_info
    COMMAND ${CMAKE_COMMAND}
        -DSOURCE_DIR=${CMAKE_SOURCE_DIR}
        -DOUTPUT=${SPHPERF_BUILD_INFO_CPP}
        -DCOMPILER=${CMAKE_CXX_COMPILER_ID}\ ${CMAKE_CXX_COMPILER_VERSION}
        -DFLAGS=${SPHPERF_BUILD_FLAGS}
        -DBUILD_TYPE=${CMAKE_BUILD_TYPE}
        -P ${CMAKE_SOURCE_DIR}/cmake/WriteBuildInfo.cmake
    BYPRODUCTS ${SPHPERF_BUILD_INFO_CPP}
    COMMENT "Recording git commit and build flags"
    VERBATIM)
