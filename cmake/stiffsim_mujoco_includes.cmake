# Debian's libmujoco-dev 2.2.2 names /usr/include/libqhull_r/ among the
# include directories of mujoco::mujoco, which need not exist (CMake then
# refuses to generate): keep only the directories that do. Included by the
# build and by the installed stiffsimConfig.cmake, after find_package(mujoco).
if(TARGET mujoco::mujoco)
  get_target_property(stiffsim_mujoco_includes mujoco::mujoco INTERFACE_INCLUDE_DIRECTORIES)
  if(stiffsim_mujoco_includes)
    set(stiffsim_mujoco_existing)
    foreach(dir IN LISTS stiffsim_mujoco_includes)
      if(EXISTS "${dir}")
        list(APPEND stiffsim_mujoco_existing "${dir}")
      endif()
    endforeach()
    set_target_properties(mujoco::mujoco PROPERTIES
                          INTERFACE_INCLUDE_DIRECTORIES "${stiffsim_mujoco_existing}")
  endif()
endif()
