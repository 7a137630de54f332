# Finds every third-party package organsmith uses. A missing package stops configure with the
# name of the Debian package that provides it (scripts/install-deps installs them all).

macro(organsmith_require pkg debian)
  find_package(${pkg} ${ARGN} QUIET)
  if(NOT ${pkg}_FOUND)
    message(FATAL_ERROR
      "organsmith: ${pkg} was not found. Install the Debian package '${debian}' "
      "(apt-get install ${debian}), or run scripts/install-deps to install everything.")
  endif()
  message(STATUS "organsmith: found ${pkg} ${${pkg}_VERSION}")
endmacro()

organsmith_require(Eigen3 libeigen3-dev 3.3 NO_MODULE)
organsmith_require(TBB libtbb-dev)
organsmith_require(ITK libinsighttoolkit5-dev 5.2
  COMPONENTS ITKCommon ITKIOImageBase ITKIOGDCM ITKIONIFTI ITKIONRRD ITKIOMeta
             ITKImageGradient ITKSmoothing)
organsmith_require(GDCM libgdcm-dev)
organsmith_require(CGAL libcgal-dev)
organsmith_require(OpenCV libopencv-dev 4 COMPONENTS core imgproc imgcodecs)
organsmith_require(embree libembree-dev 3)
organsmith_require(VTK libvtk9-dev 9.1
  COMPONENTS CommonCore CommonDataModel IOXML RenderingCore RenderingOpenGL2
             InteractionStyle RenderingFreeType IOImage RenderingAnnotation ChartsCore RenderingContext2D RenderingContextOpenGL2 FiltersCore FiltersGeneral FiltersSources FiltersGeometry)
organsmith_require(PNG libpng-dev)
organsmith_require(CLI11 libcli11-dev)
organsmith_require(nlohmann_json nlohmann-json3-dev)
organsmith_require(spdlog libspdlog-dev)
organsmith_require(GTest libgtest-dev)
organsmith_require(benchmark libbenchmark-dev)

find_package(ZLIB QUIET)
if(NOT ZLIB_FOUND)
  message(FATAL_ERROR "organsmith: zlib was not found. Install the Debian package 'zlib1g-dev', or run "
    "scripts/install-deps.")
endif()

find_package(PkgConfig QUIET)
if(PkgConfig_FOUND)
  pkg_check_modules(TOMLPP QUIET IMPORTED_TARGET tomlplusplus)
  pkg_check_modules(NETTLE QUIET IMPORTED_TARGET nettle)
endif()
if(NOT NETTLE_FOUND)
  message(FATAL_ERROR "organsmith: nettle (SHA-256) was not found. Install the Debian package "
    "'nettle-dev' (apt-get install nettle-dev), or run scripts/install-deps.")
endif()
if(NOT TOMLPP_FOUND)
  find_path(TOMLPP_INCLUDE_DIR toml++/toml.h)
  if(NOT TOMLPP_INCLUDE_DIR)
    message(FATAL_ERROR "organsmith: toml++ was not found. Install the Debian package "
      "'libtomlplusplus-dev' (apt-get install libtomlplusplus-dev), or run scripts/install-deps.")
  endif()
  add_library(PkgConfig::TOMLPP INTERFACE IMPORTED)
  target_include_directories(PkgConfig::TOMLPP INTERFACE ${TOMLPP_INCLUDE_DIR})
endif()

find_library(CSV_LIBRARY csv)
find_path(CSV_INCLUDE_DIR csv.h)
if(NOT CSV_LIBRARY OR NOT CSV_INCLUDE_DIR)
  message(FATAL_ERROR "organsmith: libcsv (CSV tables) was not found. Install the Debian package "
    "'libcsv-dev' (apt-get install libcsv-dev), or run scripts/install-deps.")
endif()
add_library(csv UNKNOWN IMPORTED)
set_target_properties(csv PROPERTIES IMPORTED_LOCATION ${CSV_LIBRARY} INTERFACE_INCLUDE_DIRECTORIES ${CSV_INCLUDE_DIR})

find_program(CCACHE_PROGRAM ccache)
if(CCACHE_PROGRAM AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  set(CMAKE_CXX_COMPILER_LAUNCHER ${CCACHE_PROGRAM})
  set(CMAKE_C_COMPILER_LAUNCHER ${CCACHE_PROGRAM})
endif()
