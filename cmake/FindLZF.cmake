# Finds liblzf (Debian: liblzf-dev), which ships no CMake package, and defines the imported target
# LZF::LZF. Installed next to minemapConfig.cmake so that a consumer of the static libminemap finds
# it on its own machine: the exported target names LZF::LZF, never this machine's absolute path.
find_path(LZF_INCLUDE_DIR lzf.h PATH_SUFFIXES liblzf)
find_library(LZF_LIBRARY lzf)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(LZF REQUIRED_VARS LZF_LIBRARY LZF_INCLUDE_DIR)
if(LZF_FOUND AND NOT TARGET LZF::LZF)
  add_library(LZF::LZF UNKNOWN IMPORTED)
  set_target_properties(LZF::LZF PROPERTIES
    IMPORTED_LOCATION "${LZF_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${LZF_INCLUDE_DIR}")
endif()
mark_as_advanced(LZF_INCLUDE_DIR LZF_LIBRARY)
