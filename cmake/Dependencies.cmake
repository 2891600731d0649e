# Finds every external dependency; a missing one stops configuration with the Debian package
# that provides it, so the fix is one command away.
find_package(PkgConfig QUIET)

macro(sphperf_missing what package)
    message(FATAL_ERROR
        "sphperf: ${what} not found. Install the Debian package '${package}' "
        "(or run scripts/install-deps.sh, which installs every dependency).")
endmacro()

if(NOT PkgConfig_FOUND)
    sphperf_missing("pkg-config" "pkg-config")
endif()

find_package(OpenMP COMPONENTS CXX)
if(NOT OpenMP_CXX_FOUND)
    sphperf_missing("OpenMP for C++" "build-essential (g++ with libgomp)")
endif()

find_package(MPI COMPONENTS CXX)
if(NOT MPI_CXX_FOUND)
    sphperf_missing("MPI" "libopenmpi-dev")
endif()

pkg_check_modules(HWLOC QUIET IMPORTED_TARGET hwloc)
if(NOT HWLOC_FOUND)
    sphperf_missing("hwloc" "libhwloc-dev")
endif()

pkg_check_modules(OPENBLAS QUIET IMPORTED_TARGET openblas)
if(NOT OPENBLAS_FOUND)
    sphperf_missing("OpenBLAS (CBLAS)" "libopenblas-dev")
endif()

find_package(nlohmann_json 3 QUIET)
if(NOT nlohmann_json_FOUND)
    sphperf_missing("nlohmann-json" "nlohmann-json3-dev")
endif()

find_package(CLI11 CONFIG QUIET)
if(NOT CLI11_FOUND)
    sphperf_missing("CLI11" "libcli11-dev")
endif()

if(SPHPERF_BUILD_TESTS)
    find_package(GTest QUIET)
    if(NOT GTest_FOUND)
        sphperf_missing("GoogleTest" "libgtest-dev")
    endif()
endif()
