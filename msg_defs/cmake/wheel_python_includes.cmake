# Work-around for ROS 2 taken from the Python package registry (ros-* wheels): their exported
# <pkg>::<pkg>__rosidl_generator_py targets carry the Python include directories of the machine
# that built the wheels (/opt/python/cp311-cp311/...), and CMake refuses to generate with
# non-existent include directories. Point them at this interpreter's headers instead. On a
# normal ROS 2 install the include directories exist and this only restates them.
# Included by msg_defs/CMakeLists.txt and msg_defs_tf2/CMakeLists.txt after find_package of
# their dependencies.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)
set(_wheel_py_includes ${Python3_INCLUDE_DIRS} ${Python3_NumPy_INCLUDE_DIRS})
# Message packages whose generator_py targets get linked (direct and transitive).
set(_wheel_py_packages builtin_interfaces std_msgs geometry_msgs service_msgs
  type_description_interfaces)
foreach(_dep IN LISTS _wheel_py_packages)
  set(_target "${_dep}::${_dep}__rosidl_generator_py")
  if(TARGET ${_target})
    get_target_property(_incs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    set(_broken FALSE)
    foreach(_inc IN LISTS _incs)
      if(_inc AND NOT IS_DIRECTORY "${_inc}")
        set(_broken TRUE)
      endif()
    endforeach()
    if(_broken)
      message(STATUS "${PROJECT_NAME}: resetting include directories of ${_target}")
      set_target_properties(${_target} PROPERTIES
        INTERFACE_INCLUDE_DIRECTORIES "${_wheel_py_includes}")
    endif()
  endif()
endforeach()
