# Included by tools/build_interfaces.py (CMAKE_PROJECT_INCLUDE) when it builds the interfaces for
# the pip set-up, where only Python loads them: the C++ generators (rosidl_generator_cpp and the
# C++ type supports) are dropped from rosidl_generate_interfaces, which then generates and
# compiles the C code, its type supports and the Python bindings only. A colcon build on a real
# ROS 2 install does not include this file and builds every language.
#
# find_package(rosidl_default_generators) registers each generator as an extension of
# rosidl_generate_idl_interfaces; the list is filtered right after it, in the caller's scope (a
# macro, as find_package's own variables are set there).
macro(find_package _cloth_sim_name)
  _find_package(${_cloth_sim_name} ${ARGN})
  if("${_cloth_sim_name}" STREQUAL "rosidl_default_generators")
    list(FILTER AMENT_EXTENSIONS_rosidl_generate_idl_interfaces
      EXCLUDE REGEX "^rosidl_(generator|typesupport|typesupport_fastrtps|typesupport_introspection)_cpp:")
  endif()
endmacro()
