# Debian 12's OpenImageIOConfig.cmake names files that the -dev package does not install, so
# OpenImageIO is found here from its header and libraries directly.
# Defines OpenImageIO_FOUND and the imported target OpenImageIO::OpenImageIO.
find_path(OpenImageIO_INCLUDE_DIR OpenImageIO/imageio.h)
find_library(OpenImageIO_LIBRARY NAMES OpenImageIO)
find_library(OpenImageIO_Util_LIBRARY NAMES OpenImageIO_Util)

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(OpenImageIO
  REQUIRED_VARS OpenImageIO_LIBRARY OpenImageIO_Util_LIBRARY OpenImageIO_INCLUDE_DIR)

if(OpenImageIO_FOUND AND NOT TARGET OpenImageIO::OpenImageIO)
  add_library(OpenImageIO::OpenImageIO UNKNOWN IMPORTED)
  set_target_properties(OpenImageIO::OpenImageIO PROPERTIES
    IMPORTED_LOCATION "${OpenImageIO_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${OpenImageIO_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${OpenImageIO_Util_LIBRARY}")
endif()
mark_as_advanced(OpenImageIO_INCLUDE_DIR OpenImageIO_LIBRARY OpenImageIO_Util_LIBRARY)
