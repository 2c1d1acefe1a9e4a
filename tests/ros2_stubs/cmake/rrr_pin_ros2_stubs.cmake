# STUB CMake packages of ament_cmake and the ROS 2 dependencies, for tests only (not ROS 2):
# each <name>Config.cmake includes this file, which gives the stub headers of ../ as the
# include directory of every dependency and records what the ament/pluginlib calls ask for.
include_guard(GLOBAL)
get_filename_component(RRR_PIN_ROS2_STUBS "${CMAKE_CURRENT_LIST_DIR}/.." ABSOLUTE)

function(ament_target_dependencies target)
  target_include_directories(${target} PUBLIC "${RRR_PIN_ROS2_STUBS}")
endfunction()

# pluginlib: the description file must exist and declare a class of the base package
function(pluginlib_export_plugin_description_file base xml)
  set(path "${CMAKE_CURRENT_SOURCE_DIR}/${xml}")
  if(NOT EXISTS "${path}")
    message(FATAL_ERROR "pluginlib_export_plugin_description_file: no ${path}")
  endif()
  file(READ "${path}" text)
  if(NOT text MATCHES "base_class_type=\"${base}::")
    message(FATAL_ERROR "${xml} declares no class of ${base}")
  endif()
  message(STATUS "STUB pluginlib: ${base} plugins in ${xml}")
endfunction()

function(ament_export_targets)
  message(STATUS "STUB ament_export_targets(${ARGN})")
endfunction()
function(ament_export_dependencies)
  message(STATUS "STUB ament_export_dependencies(${ARGN})")
endfunction()
function(ament_package)
  message(STATUS "STUB ament_package() for ${PROJECT_NAME}")
endfunction()
